//! The report and the outputs other tools read, checked from outside: features.csv has no
//! two identical columns, the corrected TIFF carries the GSF's pixel size, the ellipse plot
//! is drawn at 1:1, every picture has a scale bar and a colour bar, and report.html renders
//! in headless Chromium with every figure present and non-empty.
//!
//! The browser part runs when chromium is installed; with `DHCT_REQUIRE_BROWSER=1` its
//! absence is a failure (CI installs it).

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

fn workspace_file(relative: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests")
        .join(relative)
}

/// One `dhct correct` run of the embedded simulated graphite, shared by the tests.
fn run() -> PathBuf {
    static RUN: OnceLock<tempfile::TempDir> = OnceLock::new();
    RUN.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let output = common::correct(
            &workspace_file("data/simulated_graphite.sm4"),
            &[],
            &dir.path().join("out"),
        );
        assert!(
            output.status.success(),
            "{}",
            String::from_utf8_lossy(&output.stderr)
        );
        dir
    })
    .path()
    .join("out")
}

/// A frame fitted without local neighbour shells (the global registration: h-BN around a
/// defect, 96 × 100 px) has no local measurements: its goodness of fit says so (`null` in
/// model.json, "–" in the report), never "NaN".
#[test]
fn a_fit_without_local_measurements_shows_no_nan() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let output = common::correct(
        &workspace_file("data/real/hbn_defect_nanonis_2nm.sxm"),
        &[
            "--lattice",
            "hexagonal",
            "--nn",
            "2.504A",
            "--polarity",
            "dark",
        ],
        &out,
    );
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let model: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("model.json")).unwrap()).unwrap();
    let goodness = &model["goodness"];
    assert_eq!(goodness["local_measurements"], 0, "{goodness}");
    assert!(goodness["rms_scale_residual"].is_null(), "{goodness}");
    let report = std::fs::read_to_string(out.join("report.html")).unwrap();
    // The text a reader sees, without the embedded pictures' base64.
    let text: String = report
        .split("data:")
        .enumerate()
        .map(|(i, part)| {
            if i == 0 {
                part
            } else {
                part.split_once(['"', '\'']).map_or("", |(_, rest)| rest)
            }
        })
        .collect();
    assert!(!text.contains("NaN"), "the report shows NaN");
}

#[test]
fn features_csv_has_no_two_identical_columns() {
    let mut reader = csv::Reader::from_path(run().join("features.csv")).unwrap();
    let header: Vec<String> = reader.headers().unwrap().iter().map(String::from).collect();
    let mut columns: Vec<Vec<String>> = vec![Vec::new(); header.len()];
    for record in reader.records() {
        let record = record.unwrap();
        assert_eq!(record.len(), header.len());
        for (column, value) in columns.iter_mut().zip(record.iter()) {
            column.push(value.to_string());
        }
    }
    assert!(columns[0].len() > 100, "{} rows", columns[0].len());
    // Columns that hold one value throughout (e.g. `site` of a one-site lattice, `region`
    // of one region) say nothing twice by construction; every varying column must differ
    // from every other.
    for a in 0..header.len() {
        for b in a + 1..header.len() {
            let varying = columns[a].iter().any(|v| *v != columns[a][0]);
            assert!(
                !varying || columns[a] != columns[b],
                "features.csv columns {} and {} are identical",
                header[a],
                header[b]
            );
        }
    }
    assert!(header.contains(&"height".to_string()));
}

#[test]
fn the_corrected_tiff_has_the_pixel_size_of_the_gsf() {
    let gsf = dhct_sm4_io::read_path(&run().join("corrected_trace.gsf")).unwrap();
    let geometry = gsf.topography().unwrap().geometry().clone();
    let bytes = std::fs::read(run().join("corrected_trace.tiff")).unwrap();
    let mut decoder = tiff::decoder::Decoder::new(std::io::Cursor::new(bytes)).unwrap();
    assert_eq!(
        decoder
            .get_tag_u32(tiff::tags::Tag::ResolutionUnit)
            .unwrap(),
        3
    );
    for (tag, pitch) in [
        (tiff::tags::Tag::XResolution, geometry.pitch_x()),
        (tiff::tags::Tag::YResolution, geometry.pitch_y()),
    ] {
        let [n, d] = decoder.get_tag(tag).unwrap().into_u32_vec().unwrap()[..] else {
            panic!("{tag:?}");
        };
        let metres = 0.01 * f64::from(d) / f64::from(n);
        assert!(
            (metres / pitch - 1.0).abs() < 1e-6,
            "{metres:e} vs {pitch:e}"
        );
    }
}

/// The value of attribute `name` in the tag starting at `tag`.
fn attribute(tag: &str, name: &str) -> Option<String> {
    let end = tag.find('>')?;
    let key = format!(" {name}=\"");
    let from = tag[..end].find(&key)? + key.len();
    Some(tag[from..from + tag[from..].find('"')?].to_string())
}

fn numbers(text: &str) -> Vec<f64> {
    text.split([' ', ','])
        .filter(|t| !t.is_empty())
        .map(|t| t.parse().unwrap())
        .collect()
}

#[test]
fn the_ellipse_plot_is_drawn_at_one_to_one() {
    let svg = std::fs::read_to_string(run().join("deviation_scatter.svg")).unwrap();
    let at = svg.find("class=\"data-area\"").expect("a data area");
    let tag = &svg[svg[..at].rfind('<').unwrap()..];
    let view_box = numbers(&attribute(tag, "viewBox").unwrap());
    let width: f64 = attribute(tag, "width").unwrap().parse().unwrap();
    let height: f64 = attribute(tag, "height").unwrap().parse().unwrap();
    let (x_scale, y_scale) = (view_box[2] / width, view_box[3] / height);
    assert!(
        (x_scale / y_scale - 1.0).abs() < 1e-6,
        "Δx: {x_scale} pm/px, Δy: {y_scale} pm/px"
    );
    // The data range covers every drawn point (nothing is clipped away).
    let (x0, y0) = (view_box[0], view_box[1]);
    let (x1, y1) = (x0 + view_box[2], y0 + view_box[3]);
    let data_area = &svg[at..];
    let data_area = &data_area[..data_area.find("</svg>").unwrap()];
    let mut drawn = 0;
    for circle in data_area.split("<circle").skip(1) {
        if let (Some(cx), Some(cy)) = (attribute(circle, "cx"), attribute(circle, "cy")) {
            let (cx, cy): (f64, f64) = (cx.parse().unwrap(), cy.parse().unwrap());
            assert!(cx >= x0 && cx <= x1 && cy >= y0 && cy <= y1, "({cx}, {cy})");
            drawn += 1;
        }
    }
    assert!(drawn > 100, "{drawn} points");
}

#[test]
fn pictures_have_scale_and_colour_bars() {
    for stem in [
        "raw_trace",
        "corrected_trace",
        "ncc_trace",
        "deviation_map",
        "lattice_overlay",
        "unit_cell_averaged",
        "unit_cell_symmetrized",
    ] {
        let svg = std::fs::read_to_string(run().join(format!("{stem}.svg"))).unwrap();
        assert!(
            svg.contains("class=\"colour-bar\""),
            "{stem} has no colour bar"
        );
        assert!(
            svg.contains("class=\"scale-bar\""),
            "{stem} has no scale bar"
        );
        assert!(run().join(format!("{stem}.png")).is_file(), "{stem}.png");
    }
    let html = std::fs::read_to_string(run().join("report.html")).unwrap();
    for ascii in [
        " A,",
        " A)",
        " um",
        "(Stated)",
        "(Assumed)",
        "Right",
        "Down",
    ] {
        assert!(!html.contains(ascii), "report.html shows {ascii:?}");
    }
    assert!(html.contains("Summary") && html.contains("Assumed"));
}

/// Chromium's path, or `None` (a failure with `DHCT_REQUIRE_BROWSER=1`).
fn chromium() -> Option<&'static str> {
    let found = ["/usr/bin/chromium", "/usr/bin/chromium-browser"]
        .into_iter()
        .find(|p| Path::new(p).exists());
    if found.is_none() {
        assert!(
            std::env::var("DHCT_REQUIRE_BROWSER").as_deref() != Ok("1"),
            "DHCT_REQUIRE_BROWSER=1 but chromium is not installed (apt-get install chromium)"
        );
        println!("skipping the headless render: chromium is not installed");
    }
    found
}

/// Runs chromium headless on `page` with `mode` (`--dump-dom` or `--screenshot=…`).
fn chromium_on(chromium: &str, page: &Path, profile: &Path, mode: &str) -> String {
    let output = Command::new(chromium)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--hide-scrollbars",
            "--window-size=1280,2400",
            "--virtual-time-budget=10000",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg(mode)
        .arg(format!("file://{}", page.display()))
        .output()
        .unwrap();
    String::from_utf8_lossy(&output.stdout).into_owned()
}

/// Measures every figure after load: its SVG's rendered size and, for pictures, the
/// embedded PNG's decoded size in pixels (-1: a plot, 0: not decoded); written into the
/// DOM for `--dump-dom` (`img.decode()` never settles under virtual time: `onload`).
const PROBE: &str = r#"<script>
window.addEventListener('load', () => {
  const out = document.createElement('pre');
  out.id = 'probe';
  document.body.appendChild(out);
  const figures = [...document.querySelectorAll('figure')];
  const rows = figures.map(figure => {
    const svg = figure.querySelector('svg');
    const box = svg ? svg.getBoundingClientRect() : {width: 0, height: 0};
    return [figure.id, Math.round(box.width), Math.round(box.height), -1];
  });
  const show = () => { out.textContent = 'PROBE\n' + rows.map(r => r.join(' ')).join('\n') + '\nEND'; };
  show();
  figures.forEach((figure, k) => {
    const image = figure.querySelector('image');
    if (!image) return;
    rows[k][3] = 0;
    const img = new Image();
    img.onload = () => { rows[k][3] = img.naturalWidth * img.naturalHeight; show(); };
    img.src = image.getAttribute('href');
  });
  show();
});
</script>"#;

#[test]
fn the_report_renders_with_every_figure() {
    let Some(chromium) = chromium() else { return };
    let dir = tempfile::tempdir().unwrap();
    let html = std::fs::read_to_string(run().join("report.html")).unwrap();
    let expected: Vec<String> = html
        .split("<figure id=\"")
        .skip(1)
        .map(|s| s[..s.find('"').unwrap()].to_string())
        .collect();
    assert!(expected.len() >= 14, "{expected:?}");
    let probed = dir.path().join("report.html");
    std::fs::write(&probed, html.replace("</body>", &format!("{PROBE}</body>"))).unwrap();
    let dom = chromium_on(chromium, &probed, &dir.path().join("profile"), "--dump-dom");
    let probe = dom
        .split("PROBE\n")
        .nth(1)
        .and_then(|s| s.split("\nEND").next())
        .unwrap_or_else(|| panic!("no probe output in the DOM ({} bytes)", dom.len()));
    let rows: Vec<Vec<&str>> = probe.lines().map(|l| l.split(' ').collect()).collect();
    let ids: Vec<&str> = rows.iter().map(|r| r[0]).collect();
    assert_eq!(ids, expected, "figures rendered");
    for row in &rows {
        let (width, height, decoded): (f64, f64, i64) = (
            row[1].parse().unwrap(),
            row[2].parse().unwrap(),
            row[3].parse().unwrap(),
        );
        assert!(
            width > 200.0 && height > 100.0,
            "{} drawn {width} x {height}",
            row[0]
        );
        assert!(decoded != 0, "{}: its picture does not decode", row[0]);
        if row[0].starts_with("raw_") || row[0].starts_with("corrected_") {
            assert!(decoded >= 256 * 256, "{}: {decoded} px", row[0]);
        }
    }
    // A screenshot for people (kept when DHCT_SCREENSHOT names a file).
    if let Ok(target) = std::env::var("DHCT_SCREENSHOT") {
        let shot = dir.path().join("shot.png");
        chromium_on(
            chromium,
            &run().join("report.html"),
            &dir.path().join("profile2"),
            &format!("--screenshot={}", shot.display()),
        );
        std::fs::copy(&shot, target).unwrap();
    }
}
