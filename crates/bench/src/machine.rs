//! What the machine was doing while we measured: peak resident memory of this process and
//! the load average (the benchmark shares 2 cores with other work, so every timing is
//! reported with the load beside it).

/// Peak resident set size of this process so far (`VmHWM` in `/proc/self/status`), MiB.
/// `None` where `/proc` is unavailable.
pub fn peak_memory_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

/// Resets this process's peak resident set size (`VmHWM`) to its current size (writing 5
/// to `/proc/self/clear_refs`, Linux ≥ 4.0), so the next [`peak_memory_mib`] is the peak
/// since now. False where that is not possible.
pub fn reset_peak_memory() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

/// Peak resident memory of each stage of a run, from `VmHWM` reset as each stage starts.
#[derive(Debug, Default)]
pub struct StagePeaks {
    state: std::sync::Mutex<StagePeaksState>,
}

#[derive(Debug, Default)]
struct StagePeaksState {
    /// `(stage, peak MiB)` in order, once the stage has ended.
    ended: Vec<(String, f64)>,
    /// The stage running now.
    current: Option<String>,
}

impl StagePeaks {
    /// Ends the current stage (recording its peak) and starts `stage` (named with the
    /// resident memory it starts from, MiB).
    pub fn start(&self, stage: &str) {
        let mut state = self.state.lock().unwrap_or_else(|e| e.into_inner());
        if let (Some(previous), Some(peak)) = (state.current.take(), peak_memory_mib()) {
            state.ended.push((previous, peak));
        }
        if reset_peak_memory() {
            let resident = current_memory_mib().unwrap_or(f64::NAN);
            state.current = Some(format!("{stage} (from {resident:.0})"));
        }
    }

    /// Ends the current stage; every stage's peak, MiB.
    pub fn finish(&self) -> Vec<(String, f64)> {
        self.start("");
        let mut state = self.state.lock().unwrap_or_else(|e| e.into_inner());
        state.current = None;
        std::mem::take(&mut state.ended)
    }
}

/// Current resident set size of this process (`VmRSS`), MiB.
pub fn current_memory_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

/// The 1-, 5- and 15-minute load averages (runnable processes), from `/proc/loadavg`.
pub fn load_average() -> Option<[f64; 3]> {
    let text = std::fs::read_to_string("/proc/loadavg").ok()?;
    let mut fields = text.split_whitespace().map(|f| f.parse::<f64>().ok());
    Some([fields.next()??, fields.next()??, fields.next()??])
}

/// The load average as `"l1 l5 l15"`, or `"unknown"`.
pub fn load_string() -> String {
    load_average()
        .map(|[a, b, c]| format!("{a:.2} {b:.2} {c:.2}"))
        .unwrap_or_else(|| "unknown".into())
}

/// Logical CPUs available to this process.
pub fn cpus() -> usize {
    std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
}

/// Clock ticks per second of `/proc` CPU times (`sysconf(_SC_CLK_TCK)`, 100 on Linux).
const CLOCK_TICKS_PER_S: f64 = 100.0;

/// Busy CPU time of the whole machine, all CPUs (user + nice + system + irq + softirq +
/// steal, from the `cpu` line of `/proc/stat`), seconds.
pub fn machine_busy_s() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/stat").ok()?;
    let line = text.lines().find(|l| l.starts_with("cpu "))?;
    let v: Vec<f64> = line
        .split_whitespace()
        .skip(1)
        .map(|f| f.parse().unwrap_or(0.0))
        .collect();
    // user nice system idle iowait irq softirq steal
    let busy = v.first()? + v.get(1)? + v.get(2)? + v.get(5)? + v.get(6)? + v.get(7)?;
    Some(busy / CLOCK_TICKS_PER_S)
}

/// CPU time of this process, all threads (user + system from `/proc/self/stat`), seconds.
pub fn process_cpu_s() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the parenthesised command name; utime and stime are fields 14 and 15.
    let rest = &text[text.rfind(')')? + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let utime: f64 = fields.get(11)?.parse().ok()?;
    let stime: f64 = fields.get(12)?.parse().ok()?;
    Some((utime + stime) / CLOCK_TICKS_PER_S)
}

/// CPU use of everything except this process between two samples.
#[derive(Debug, Clone, Copy)]
pub struct ContentionProbe {
    machine_busy_s: Option<f64>,
    process_s: Option<f64>,
    start: std::time::Instant,
}

impl ContentionProbe {
    /// Starts measuring.
    pub fn start() -> ContentionProbe {
        ContentionProbe {
            machine_busy_s: machine_busy_s(),
            process_s: process_cpu_s(),
            start: std::time::Instant::now(),
        }
    }

    /// Mean number of CPUs that other processes kept busy since [`ContentionProbe::start`]
    /// (0 = the machine was ours alone; resolution 10 ms of CPU time).
    pub fn other_cpus(&self) -> Option<f64> {
        let wall = self.start.elapsed().as_secs_f64();
        let machine = machine_busy_s()? - self.machine_busy_s?;
        let own = process_cpu_s()? - self.process_s?;
        Some(((machine - own) / wall).max(0.0))
    }
}
