//! Prints the strongest spectral peaks of a scan file's trace:
//! `cargo run -p dhct-calibrate --example peaks -- FILE`.

use dhct_calibrate::PowerSpectrum;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args().nth(1).ok_or("usage: peaks FILE")?;
    let file = dhct_sm4_io::read_path(path.as_ref())?;
    let pair = file.topography().ok_or("no topography")?;
    let geometry = pair.geometry();
    let trace = pair.trace().ok_or("no trace")?;
    let spectrum = PowerSpectrum::of(trace.z.view(), None, geometry.fast_axis())?;
    let (fx, fy) = (
        1.0 / (spectrum.columns as f64 * geometry.pitch_x()),
        1.0 / (spectrum.rows as f64 * geometry.pitch_y()),
    );
    for p in spectrum.peaks().iter().take(30) {
        let g = (p.k[0] * fx).hypot(p.k[1] * fy);
        println!(
            "k = ({:7.2}, {:7.2}) bins  period {:8.3} Å  angle {:6.1}°  power {:.3e}  snr {:.0}",
            p.k[0],
            p.k[1],
            1e10 / g,
            (p.k[1] * fy).atan2(p.k[0] * fx).to_degrees(),
            p.power,
            p.snr
        );
    }
    Ok(())
}
