//! The hostile corpus against the built `dhct`: special files, truncated and absurd files,
//! extreme options, hostile lattice and simulator files. Every run gets 20 s and a 4 GB
//! address space (`prlimit --as`, else `ulimit -v`) and must end with a non-zero exit, a
//! message naming the problem, no panic, and no NaN or infinity in any JSON or CSV it wrote.
//! The slow cases run against tiny inputs so the whole corpus takes well under a minute.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use dhct_scan::{FileFormat, ImageChannel, ScanDirection, ScanFile, ScanGeometry, ScanPair};
use ndarray::Array2;

/// Wall-clock limit of one run.
const TIME_LIMIT: Duration = Duration::from_secs(20);

/// Address-space limit of one run, bytes.
const MEMORY_LIMIT: u64 = 4 << 30;

fn workspace_file(relative: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests")
        .join(relative)
}

/// `dhct args…` under the time and memory limits; returns (exit code, stdout, stderr).
fn run_limited(args: &[&str], dir: &Path) -> (Option<i32>, String, String) {
    let bin = env!("CARGO_BIN_EXE_dhct");
    let has_prlimit = Command::new("prlimit")
        .arg("--version")
        .stdout(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    let mut command = if has_prlimit {
        let mut c = Command::new("prlimit");
        c.arg(format!("--as={MEMORY_LIMIT}")).arg("--").arg(bin);
        c.args(args);
        c
    } else {
        let mut c = Command::new("bash");
        let quoted: Vec<String> = args.iter().map(|a| format!("'{a}'")).collect();
        c.arg("-c").arg(format!(
            "ulimit -v {}; exec '{bin}' {}",
            MEMORY_LIMIT / 1024,
            quoted.join(" ")
        ));
        c
    };
    let (out_path, err_path) = (dir.join("stdout.txt"), dir.join("stderr.txt"));
    let mut child = command
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(std::fs::File::create(&out_path).unwrap())
        .stderr(std::fs::File::create(&err_path).unwrap())
        .spawn()
        .expect("run dhct");
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if start.elapsed() > TIME_LIMIT {
            let _ = child.kill();
            let _ = child.wait();
            panic!("dhct {args:?} ran over {TIME_LIMIT:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let read = |p: &Path| std::fs::read_to_string(p).unwrap_or_default();
    (status.code(), read(&out_path), read(&err_path))
}

/// Every JSON and CSV file under `dir` holds no NaN or infinity (JSON's `null` is the
/// documented "not determined", see the README).
fn assert_no_non_finite(dir: &Path) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.filter_map(|e| e.ok()) {
        let path = entry.path();
        if path.is_dir() {
            assert_no_non_finite(&path);
            continue;
        }
        let ext = path.extension().map(|e| e.to_string_lossy().to_lowercase());
        if !matches!(ext.as_deref(), Some("json" | "csv")) {
            continue;
        }
        let text = std::fs::read_to_string(&path).unwrap_or_default();
        for token in text.split(|c: char| !(c.is_ascii_alphanumeric() || c == '.')) {
            let lower = token.to_ascii_lowercase();
            assert!(
                !(lower == "nan" || lower == "inf" || lower == "infinity"),
                "{} holds {token}",
                path.display()
            );
        }
    }
}

/// Runs `args` in a scratch folder and checks the outcome: refused (non-zero exit), no
/// panic, the message holds every one of `expected` (case-insensitive), no NaN in output.
fn refused(args: &[&str], dir: &Path, expected: &[&str]) {
    let (code, stdout, stderr) = run_limited(args, dir);
    let text = format!("{stdout}\n{stderr}");
    assert!(
        !stderr.contains("panicked"),
        "dhct {args:?} panicked:\n{stderr}"
    );
    assert!(
        code.is_some_and(|c| c != 0),
        "dhct {args:?} was not refused (exit {code:?}):\n{text}"
    );
    assert_ne!(code, Some(101), "dhct {args:?} panicked:\n{text}");
    let lower = text.to_lowercase();
    for word in expected {
        assert!(
            lower.contains(&word.to_lowercase()),
            "dhct {args:?}: the message does not name {word:?}:\n{text}"
        );
    }
    assert_no_non_finite(dir);
}

fn mkfifo(path: &Path) -> bool {
    Command::new("mkfifo")
        .arg(path)
        .status()
        .is_ok_and(|s| s.success())
}

#[test]
fn special_files_are_refused_at_every_entry_point_without_blocking() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let example = workspace_file("data/simulated_graphite.sm4");
    let example = example.to_str().unwrap();
    let fifo = d.join("pipe.sm4");
    let fifo_dir = d.join("fifos");
    std::fs::create_dir(&fifo_dir).unwrap();
    if mkfifo(&fifo) && mkfifo(&fifo_dir.join("scan.sm4")) {
        let f = fifo.to_str().unwrap();
        refused(&["info", f], d, &["named pipe", "pipe.sm4"]);
        refused(&["correct", f, "-o", "out"], d, &["named pipe"]);
        refused(&["diagnose", f, "-o", "out"], d, &["named pipe"]);
        refused(
            &["batch", fifo_dir.to_str().unwrap(), "-o", "out"],
            d,
            &["no scan files"],
        );
        refused(
            &["correct", example, "--mask", f, "-o", "out"],
            d,
            &["named pipe"],
        );
        refused(
            &["correct", example, "--config", f, "-o", "out"],
            d,
            &["named pipe"],
        );
        refused(
            &["correct", example, "--lattice", f, "-o", "out"],
            d,
            &["named pipe"],
        );
        refused(&["simulate", f, "-o", "out"], d, &["named pipe"]);
    } else {
        eprintln!("note: mkfifo is not available; the FIFO cases were not run");
    }
    for device in ["/dev/zero", "/dev/urandom"] {
        if Path::new(device).exists() {
            refused(&["info", device], d, &["device"]);
            refused(&["correct", device, "-o", "out"], d, &["device"]);
            refused(
                &["correct", example, "--mask", device, "-o", "out"],
                d,
                &["device"],
            );
        }
    }
    refused(&["info", d.to_str().unwrap()], d, &["directory"]);
    refused(
        &["correct", d.to_str().unwrap(), "-o", "out"],
        d,
        &["directory"],
    );
}

#[test]
fn truncated_and_absurd_files_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let bytes = std::fs::read(workspace_file("data/simulated_graphite.sm4")).unwrap();
    for cut in [0, 10, 1000, bytes.len() / 2] {
        let path = d.join(format!("cut{cut}.sm4"));
        std::fs::write(&path, &bytes[..cut]).unwrap();
        let p = path.to_str().unwrap();
        let name = format!("cut{cut}.sm4");
        refused(&["info", p], d, &[&name]);
        refused(&["correct", p, "-o", "out"], d, &["cannot read", &name]);
    }
    // A GSF whose scan angle is 1e300 radians and one whose size is garbage.
    for (name, line, key) in [
        ("angle.gsf", "DHCT_ScanAngle = 1e300", "DHCT_ScanAngle"),
        ("size.gsf", "XReal = garbage", "XReal"),
    ] {
        let mut file =
            format!("Gwyddion Simple Field 1.0\nXRes = 2\nYRes = 2\nYReal = 1e-9\n{line}\n")
                .into_bytes();
        if !line.starts_with("XReal") {
            file.extend_from_slice(b"XReal = 1e-9\n");
        }
        let padding = 4 - file.len() % 4;
        file.extend(std::iter::repeat_n(0u8, padding));
        file.extend(std::iter::repeat_n(0u8, 16));
        let path = d.join(name);
        std::fs::write(&path, file).unwrap();
        refused(&["info", path.to_str().unwrap()], d, &[key]);
    }
}

/// A small graphite image as NPY (64 x 64 px): enough to reach option validation quickly.
fn small_npy(d: &Path) -> String {
    let z = Array2::from_shape_fn((64, 64), |(r, c)| {
        ((r as f64 * 1.1).sin() + (c as f64 * 0.9).cos()) * 1e-11
    });
    let mut bytes = Vec::new();
    dhct_sm4_io::npy::write(&ImageChannel::new("z", "m", z), &mut bytes).unwrap();
    let path = d.join("small.npy");
    std::fs::write(&path, bytes).unwrap();
    path.to_str().unwrap().to_string()
}

#[test]
fn extreme_options_are_refused_naming_key_value_and_range() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let input = small_npy(d);
    for (section, key) in [
        (
            "[pipeline.dhct.neighbours]\nrdf_shells = 10000",
            "rdf_shells",
        ),
        (
            "[pipeline.dhct.fit]\nrobust_rounds = 1000000",
            "robust_rounds",
        ),
        (
            "[pipeline.dhct.neighbours]\nbin_fraction = 1e-9",
            "bin_fraction",
        ),
        (
            "[pipeline.lattice_fit]\ninitial_radius = nan",
            "initial_radius",
        ),
        ("[pipeline.features]\nthreshold = inf", "threshold"),
        (
            "[pipeline.lattice_fit]\ninitial_radiuss = 3.0",
            "did you mean",
        ),
        ("[geometry]\npixel_period = 1e30", "pixel_period"),
    ] {
        let config = d.join("config.toml");
        std::fs::write(&config, section).unwrap();
        refused(
            &["correct", &input, "--config", "config.toml", "-o", "out"],
            d,
            &[key],
        );
    }
    refused(
        &["correct", &input, "--pixel-period", "1e30", "-o", "out"],
        d,
        &["pixel_period", "1e30"],
    );
    refused(&["info", &input, "--pitch", "1e300"], d, &["pitch"]);
    refused(
        &["correct", &input, "--nn", "1e30", "-o", "out"],
        d,
        &["nn"],
    );
}

#[test]
fn hostile_lattice_files_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let input = small_npy(d);
    let header = "name = 'x'\nlength_unit = 'A'\n";
    let many: String = (0..10_000)
        .map(|k| {
            format!(
                "[[motif]]\nfractional = [{}, {}]\n",
                (k % 100) as f64 / 100.0,
                (k / 100) as f64 / 100.0
            )
        })
        .collect();
    for (name, body, expected) in [
        (
            "many.toml",
            format!("{header}a1 = [300.0, 0.0]\na2 = [0.0, 300.0]\n{many}"),
            "10000 sites",
        ),
        (
            "parallel.toml",
            format!(
                "{header}a1 = [3.0, 0.0]\na2 = [3.0, 0.001]\n[[motif]]\nfractional = [0.0, 0.0]\n"
            ),
            "nearly parallel",
        ),
        (
            "huge.toml",
            format!(
                "{header}a1 = [3.0, 0.0]\na2 = [0.0, 3.0]\n[[motif]]\nfractional = [1e300, 0.0]\n"
            ),
            "1000 cells",
        ),
    ] {
        std::fs::write(d.join(name), body).unwrap();
        refused(
            &["correct", &input, "--lattice", name, "-o", "out"],
            d,
            &[expected],
        );
    }
}

#[test]
fn hostile_simulator_configs_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut config = dhct_simulate::presets::ci_small();
    let effect = config.effects[0].clone();
    config.effects = vec![effect; 10_000];
    std::fs::write(d.join("effects.toml"), config.to_toml_string().unwrap()).unwrap();
    refused(
        &["simulate", "effects.toml", "-o", "sim"],
        d,
        &["10000 effects"],
    );
    let mut config = dhct_simulate::presets::ci_small();
    config.scan.columns = 16384;
    config.scan.rows = 16384;
    std::fs::write(d.join("big.toml"), config.to_toml_string().unwrap()).unwrap();
    refused(
        &["simulate", "big.toml", "-o", "sim"],
        d,
        &["16384 x 16384", "GB"],
    );
}

#[test]
fn an_image_of_only_infinities_and_huge_values_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let extreme = |value: f64| {
        Array2::from_shape_fn(
            (64, 64),
            move |(r, c)| if (r + c) % 2 == 0 { value } else { -value },
        )
    };
    // Mostly an ordinary image with a few values at the ends of the f64 range.
    let mut mixed = Array2::from_shape_fn((64, 64), |(r, c)| {
        ((r as f64 * 1.1).sin() + (c as f64 * 0.9).cos()) * 1e-11
    });
    mixed[[3, 4]] = 1e308;
    mixed[[10, 40]] = -1e308;
    mixed[[20, 20]] = f64::INFINITY;
    for (name, z) in [
        ("inf.npy", extreme(f64::INFINITY)),
        ("huge.npy", extreme(1e308)),
        ("mixed.npy", mixed),
    ] {
        let mut bytes = Vec::new();
        dhct_sm4_io::npy::write(&ImageChannel::new("z", "m", z), &mut bytes).unwrap();
        std::fs::write(d.join(name), bytes).unwrap();
        for extra in [None, Some("--trust-inputs")] {
            let mut args = vec!["correct", name, "-o", "out"];
            args.extend(extra);
            refused(&args, d, &["error"]);
        }
    }
}

#[test]
fn unusable_scan_timing_is_reported_not_silent() {
    // An SM4 whose pages state a NaN period: `info` marks the timing assumed and says why.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let z = Array2::from_shape_fn((8, 8), |(r, c)| (r * c) as f64 * 1e-12);
    let geometry = ScanGeometry::new(
        8,
        8,
        1e-10,
        1e-10,
        1e-3,
        ScanDirection::Right,
        ScanDirection::Down,
    )
    .unwrap();
    let pair = ScanPair::new(
        geometry,
        ImageChannel::new("Topography", "m", z.clone()),
        Some(ImageChannel::new("Topography", "m", z)),
    )
    .unwrap();
    let file = ScanFile {
        format: FileFormat::RhkSm4,
        pairs: vec![pair],
        metadata: Default::default(),
    };
    let mut bytes = Vec::new();
    dhct_sm4_io::sm4::write(&file, &mut bytes).unwrap();
    // Patch both page headers' period (byte 84 of each header) to NaN.
    let u32_at = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
    for header in [u32_at(98 + 36), u32_at(98 + 56 + 36)] {
        bytes[header + 84..header + 88].copy_from_slice(&f32::NAN.to_le_bytes());
    }
    std::fs::write(d.join("nan.sm4"), &bytes).unwrap();
    let (code, stdout, stderr) = run_limited(&["info", "nan.sm4"], d);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        stdout.contains("assumed") && stdout.contains("period NaN"),
        "{stdout}"
    );
}

#[test]
fn output_folders_are_replaced_only_with_overwrite_and_locked_while_written() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let example = workspace_file("data/simulated_graphite.sm4");
    let example = example.to_str().unwrap();
    let args = ["correct", example, "--quiet", "-o", "out"];
    let (code, _, stderr) = run_limited(&args, d);
    assert_eq!(code, Some(0), "{stderr}");
    std::fs::write(d.join("out/stale_from_an_old_run.csv"), "x").unwrap();
    // A second run into the same folder: refused without --overwrite …
    refused(
        &args,
        d,
        &["already holds an earlier dhct run", "--overwrite"],
    );
    // … and with it, the folder is replaced whole: the stale file is gone.
    let (code, _, stderr) = run_limited(&[&args[..], &["--overwrite"]].concat(), d);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(d.join("out/model.json").is_file());
    assert!(!d.join("out/stale_from_an_old_run.csv").exists());
    // Nothing but the output is left beside it (no staging folder, lock or temporary).
    let mut names: Vec<String> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["out", "stderr.txt", "stdout.txt"]);
    // A folder of someone else's files is never replaced.
    std::fs::create_dir(d.join("photos")).unwrap();
    std::fs::write(d.join("photos/holiday.jpg"), "x").unwrap();
    refused(
        &["correct", example, "--overwrite", "-o", "photos"],
        d,
        &["did not write"],
    );
    assert!(d.join("photos/holiday.jpg").is_file());
    // A live lock (held by a running process named dhct…) stops a run; a dead one is taken
    // over.
    let mut holder = Command::new("bash")
        .args(["-c", "exec -a dhct-lock-holder sleep 30"])
        .spawn()
        .expect("start a lock holder");
    std::fs::write(d.join(".locked.dhct-lock"), format!("{}\n", holder.id())).unwrap();
    std::thread::sleep(Duration::from_millis(200));
    let (code, _, stderr) = run_limited(&["correct", example, "--quiet", "-o", "locked"], d);
    let _ = holder.kill();
    let _ = holder.wait();
    assert_ne!(code, Some(0));
    assert!(stderr.contains("another dhct run"), "{stderr}");
    std::fs::write(d.join(".locked.dhct-lock"), "4294967290\n").unwrap();
    std::fs::create_dir(d.join(".locked.dhct-staging-4294967290")).unwrap();
    let (code, _, stderr) = run_limited(&["correct", example, "--quiet", "-o", "locked"], d);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(!d.join(".locked.dhct-staging-4294967290").exists());
    assert!(!d.join(".locked.dhct-lock").exists());
}

#[test]
fn batch_outputs_of_inputs_sharing_a_stem_do_not_collide() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let inputs = d.join("in");
    std::fs::create_dir(&inputs).unwrap();
    std::fs::copy(
        workspace_file("data/simulated_graphite.sm4"),
        inputs.join("a.sm4"),
    )
    .unwrap();
    std::fs::copy(
        workspace_file("data/simulated_graphite.sm4"),
        inputs.join("a.tif"),
    )
    .unwrap();
    let (code, stdout, stderr) = run_limited(&["batch", "in", "--quiet", "-o", "out"], d);
    // a.tif is an SM4 in disguise (read by content), so both succeed.
    assert_eq!(code, Some(0), "{stdout}\n{stderr}");
    for folder in ["a_sm4", "a_tif"] {
        assert!(
            d.join("out").join(folder).join("model.json").is_file(),
            "missing {folder}: {stdout}"
        );
    }
    assert!(!d.join("out/a").exists());
    assert_no_non_finite(&d.join("out"));
}
