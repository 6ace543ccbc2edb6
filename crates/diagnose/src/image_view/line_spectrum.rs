//! One scan line's spectrum: the longest run of modelled pixels in it, Hann-windowed and
//! transformed, so that the along-line search and the passes' phases read the same spectra.

use realfft::num_complex::Complex;

/// A line whose longest run of modelled pixels is shorter than its length over this is
/// left out.
pub(crate) const MIN_RUN_FRACTION_OF_LINE: usize = 4;

/// The longest run of consecutive finite values.
pub(crate) fn longest_finite_run(values: &[f64]) -> std::ops::Range<usize> {
    let (mut best, mut start) = (0..0, None);
    for (i, v) in values.iter().chain([&f64::NAN]).enumerate() {
        match (v.is_finite(), start) {
            (true, None) => start = Some(i),
            (false, Some(s)) => {
                if i - s > best.len() {
                    best = s..i;
                }
                start = None;
            }
            _ => {}
        }
    }
    best
}

/// The spectrum of `line`'s values in `run` (finite), Hann-windowed over the run and
/// zero elsewhere (so that phases refer to the line's first pixel), scaled by `n/m` (`m`
/// the run's length): a sinusoid's peak is the same however long the run.
pub(crate) fn windowed_spectrum(
    fft: &dyn realfft::RealToComplex<f64>,
    line: &[f64],
    run: std::ops::Range<usize>,
    n: usize,
) -> Option<Vec<Complex<f64>>> {
    let m = run.len();
    let values = &line[run.clone()];
    let mean = values.iter().sum::<f64>() / m as f64;
    let mut input = fft.make_input_vec();
    for (i, (slot, v)) in input[run].iter_mut().zip(values).enumerate() {
        let w = (std::f64::consts::PI * (i as f64 + 0.5) / m as f64)
            .sin()
            .powi(2);
        *slot = (v - mean) * w;
    }
    let mut output = fft.make_output_vec();
    fft.process(&mut input, &mut output).ok()?;
    let scale = n as f64 / m as f64;
    Some(output.into_iter().map(|c| c * scale).collect())
}
