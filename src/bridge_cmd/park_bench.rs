//! `qicp bench bridge-park`: the park drive in one process against two over the bridge.

use super::*;

/// Arguments of `qicp bench bridge-park`.
#[derive(Debug, Clone, clap::Args)]
pub struct ParkBenchArgs {
    /// The drive to simulate.
    #[arg(default_value = "configs/worlds/park.toml")]
    pub config: PathBuf,
    /// Matcher kind.
    #[arg(long, default_value = "q-wsm")]
    pub matcher: String,
    /// Runs of each arm, interleaved (in-process, two-process, in-process, …).
    #[arg(long, default_value_t = 7)]
    pub runs: usize,
    /// Scratch directory for the outputs: must not exist yet (it is created) or be an empty
    /// directory of this user, not a link; it is made private (0700) and kept. Default: a
    /// fresh private directory with a random name under the system's temp dir, removed at
    /// the end.
    #[arg(long)]
    pub scratch: Option<PathBuf>,
    /// Print one JSON object instead of a line.
    #[arg(long)]
    pub json: bool,
    /// Internal: be the in-process arm, writing its outputs to this directory.
    #[arg(long, hide = true)]
    pub in_process_once: Option<PathBuf>,
}

/// Wall times of one arm (s).
#[derive(Debug, Clone, Serialize)]
pub struct ArmTimes {
    /// Median over the runs.
    pub median_s: f64,
    /// Every run, in order.
    pub runs_s: Vec<f64>,
    /// CPU time (user + system) of the arm's processes, mean per run (s; from the kernel's
    /// accounting of reaped children, 10 ms ticks; `null` where /proc is missing).
    pub cpu_s: Option<f64>,
}

impl ArmTimes {
    fn of(runs_s: Vec<f64>, cpu_total_s: Option<f64>) -> Self {
        let n = runs_s.len().max(1) as f64;
        Self {
            median_s: quantile(&runs_s, 0.5),
            runs_s,
            cpu_s: cpu_total_s.map(|c| c / n),
        }
    }
}

/// CPU seconds (user + system) of this process's reaped children so far: `cutime + cstime`
/// of /proc/self/stat, in USER_HZ (100 per second on Linux).
pub(super) fn children_cpu_s() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which may hold spaces) start at field 3 (state);
    // cutime and cstime are fields 16 and 17.
    let rest = &stat[stat.rfind(')')? + 1..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| fields.get(i - 3)?.parse::<f64>().ok();
    Some((ticks(16)? + ticks(17)?) / 100.0)
}

/// Result of `qicp bench bridge-park`.
#[derive(Debug, Clone, Serialize)]
pub struct ParkBenchReport {
    /// The drive.
    pub config: String,
    /// The matcher.
    pub matcher: String,
    /// Scans in the drive.
    pub scans: u64,
    /// `qicp bench bridge-park CONFIG --in-process-once DIR`: simulate and match in one
    /// process; spawn to exit.
    pub in_process: ArmTimes,
    /// `qicp match --subscribe …` and `qicp sim CONFIG --publish …` spawned together; spawn
    /// of the first to exit of the last.
    pub two_process: ArmTimes,
    /// `two_process.median_s / in_process.median_s`.
    pub ratio: f64,
    /// Whether every two-process trajectory equals the in-process one byte for byte.
    pub identical: bool,
    /// /proc/loadavg (1, 5, 15 min) at the start and at the end.
    pub load: [[f64; 3]; 2],
}

pub(super) fn load_average() -> [f64; 3] {
    let text = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let mut it = text
        .split_whitespace()
        .map(|w| w.parse::<f64>().unwrap_or(f64::NAN));
    [
        it.next().unwrap_or(f64::NAN),
        it.next().unwrap_or(f64::NAN),
        it.next().unwrap_or(f64::NAN),
    ]
}

/// The in-process arm: simulate the drive and match each scan as it is produced, then write
/// what `qicp match --subscribe --out` writes (trajectory, per-scan figures, config, summary).
pub(super) fn park_in_process(config: &Path, kind: &str, out: &Path) -> Result<()> {
    let cfg = qicp_sim::SimConfig::load(config)?;
    let mut matcher = crate::registry().config(kind)?;
    matcher.validate()?;
    matcher.fill_defaults();
    let mut matching = Matching::new(&matcher)?;
    for record in qicp_sim::Simulation::new(cfg)? {
        matching.push(&record?);
    }
    let run = matching.finish();
    write_run(out, &run, &matcher)?;
    let text = serde_json::to_string_pretty(&run.summary)?;
    crate::matching::write_atomic(&out.join("summary.json"), text.as_bytes())?;
    Ok(())
}

/// Waits for every child (polling each millisecond, at most `timeout`); fails on a non-zero
/// exit or the timeout (killing what still runs). Returns the stdout of each.
pub(super) fn wait_all(
    children: &mut [(&'static str, std::process::Child)],
    timeout: Duration,
) -> Result<Vec<String>> {
    use std::io::Read;
    let deadline = Instant::now() + timeout;
    let mut done = vec![false; children.len()];
    let kill_all = |children: &mut [(&'static str, std::process::Child)]| {
        for (_, c) in children.iter_mut() {
            let _ = c.kill();
            let _ = c.wait();
        }
    };
    while done.iter().any(|d| !d) {
        let mut failed = None;
        for (i, (name, child)) in children.iter_mut().enumerate() {
            if done[i] {
                continue;
            }
            if let Some(status) = child.try_wait()? {
                done[i] = true;
                if !status.success() {
                    let mut err = String::new();
                    if let Some(mut s) = child.stderr.take() {
                        let _ = s.read_to_string(&mut err);
                    }
                    failed = Some(format!("{name} failed ({status}): {err}"));
                    break;
                }
            }
        }
        if let Some(failure) = failed {
            kill_all(children);
            bail!(failure);
        }
        if Instant::now() > deadline {
            kill_all(children);
            bail!("bench children did not finish within {timeout:?}");
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    let mut outs = Vec::new();
    for (_, child) in children.iter_mut() {
        let mut out = String::new();
        if let Some(mut s) = child.stdout.take() {
            s.read_to_string(&mut out)?;
        }
        outs.push(out);
    }
    Ok(outs)
}

/// Runs `qicp bench bridge-park`: the whole park drive matched in one process against the
/// same drive published by `qicp sim --publish` to `qicp match --subscribe`, both arms run
/// as fresh processes of this binary, interleaved, `--runs` times each.
pub fn run_park_bench(args: &ParkBenchArgs) -> Result<()> {
    if let Some(out) = &args.in_process_once {
        return park_in_process(&args.config, &args.matcher, out);
    }
    anyhow::ensure!(args.runs > 0, "--runs must be at least 1");
    let exe = std::env::current_exe().context("locating the qicp binary")?;
    let scratch = Scratch::prepare(args.scratch.as_deref())?;
    let scratch = scratch.path();
    let config = args.config.to_string_lossy().to_string();
    let kind = crate::registry().config(&args.matcher)?.kind();
    let kind = kind.as_str();
    let spawn =
        |name: &'static str, argv: &[&str]| -> Result<(&'static str, std::process::Child)> {
            let child = std::process::Command::new(&exe)
                .args(argv)
                .stdin(std::process::Stdio::null())
                .stdout(std::process::Stdio::piped())
                .stderr(std::process::Stdio::piped())
                .spawn()
                .with_context(|| format!("spawning {name}"))?;
            Ok((name, child))
        };
    let timeout = Duration::from_secs(300);
    let load_start = load_average();
    let (mut inproc, mut twoproc) = (Vec::new(), Vec::new());
    let (mut inproc_cpu, mut twoproc_cpu) = (Some(0.0), Some(0.0));
    let add = |total: &mut Option<f64>, before: Option<f64>| {
        *total = match (*total, before, children_cpu_s()) {
            (Some(t), Some(b), Some(a)) => Some(t + a - b),
            _ => None,
        };
    };
    let mut identical = true;
    let mut scans = 0;
    for run in 0..args.runs {
        let one = scratch.join("in-process");
        Scratch::clear(&one)?;
        let one_s = one.to_string_lossy().to_string();
        let cpu0 = children_cpu_s();
        let t0 = Instant::now();
        let mut children = vec![spawn(
            "in-process run",
            &[
                "bench",
                "bridge-park",
                &config,
                "--matcher",
                kind,
                "--in-process-once",
                &one_s,
            ],
        )?];
        wait_all(&mut children, timeout)?;
        inproc.push(t0.elapsed().as_secs_f64());
        add(&mut inproc_cpu, cpu0);

        let two = scratch.join("two-process");
        Scratch::clear(&two)?;
        let two_s = two.to_string_lossy().to_string();
        let prefix = format!("qicp-bench-park-{}-{run}", std::process::id());
        let cpu0 = children_cpu_s();
        let t0 = Instant::now();
        let mut children = vec![
            spawn(
                "qicp match --subscribe",
                &[
                    "match",
                    "--subscribe",
                    "--matcher",
                    kind,
                    "--service-prefix",
                    &prefix,
                    "--out",
                    &two_s,
                ],
            )?,
            spawn(
                "qicp sim --publish",
                &["sim", &config, "--publish", "--service-prefix", &prefix],
            )?,
        ];
        let outs = wait_all(&mut children, timeout)?;
        twoproc.push(t0.elapsed().as_secs_f64());
        add(&mut twoproc_cpu, cpu0);
        let report: serde_json::Value =
            serde_json::from_str(&outs[1]).context("reading the publisher's report")?;
        scans = report["published"].as_u64().unwrap_or(0);
        let read = |d: &Path| std::fs::read(d.join("trajectory.tum")).unwrap_or_default();
        identical &= !read(&one).is_empty() && read(&one) == read(&two);
    }
    let in_process = ArmTimes::of(inproc, inproc_cpu);
    let two_process = ArmTimes::of(twoproc, twoproc_cpu);
    let report = ParkBenchReport {
        config,
        matcher: kind.to_string(),
        scans,
        ratio: two_process.median_s / in_process.median_s,
        in_process,
        two_process,
        identical,
        load: [load_start, load_average()],
    };
    if args.json {
        qicp_core::say!("{}", serde_json::to_string(&report)?)?;
    } else {
        let cpu = |a: &ArmTimes| a.cpu_s.map_or("?".to_string(), |c| format!("{c:.3}"));
        qicp_core::say!(
            "{} scans, {}: in-process {:.3} s, two processes {:.3} s (median of {}), ratio {:.3}; \
             CPU per run {} s against {} s; load {:.2}{}",
            report.scans,
            report.matcher,
            report.in_process.median_s,
            report.two_process.median_s,
            args.runs,
            report.ratio,
            cpu(&report.in_process),
            cpu(&report.two_process),
            report.load[0][0],
            if report.identical {
                ""
            } else {
                "; TRAJECTORIES DIFFER"
            }
        )?;
    }
    anyhow::ensure!(report.identical, "the two-process trajectory differs");
    Ok(())
}

/// The scratch directory of `qicp bench bridge-park`, private to this user so that nobody
/// can plant a link in it for the runs to write through.
#[derive(Debug)]
pub(super) enum Scratch {
    /// Fresh, random name, 0700, removed when dropped.
    Temporary(tempfile::TempDir),
    /// The user's `--scratch`, kept.
    Given(PathBuf),
}

impl Scratch {
    /// A fresh private directory, or the user's `given` one if it does not exist yet (it is
    /// created, 0700) or is an empty directory of this user that is not a link (it is made
    /// 0700).
    fn prepare(given: Option<&Path>) -> Result<Self> {
        use std::os::unix::fs::{DirBuilderExt, MetadataExt, PermissionsExt};
        let Some(dir) = given else {
            let dir = tempfile::Builder::new()
                .prefix("qicp-bench-park-")
                .permissions(std::fs::Permissions::from_mode(0o700))
                .tempdir()
                .context("creating a scratch directory")?;
            return Ok(Scratch::Temporary(dir));
        };
        let refuse = |why: &str| anyhow::anyhow!("--scratch {}: {why}", dir.display());
        match std::fs::symlink_metadata(dir) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                // mkdir does not follow a link planted meanwhile: it fails on any entry.
                std::fs::DirBuilder::new()
                    .mode(0o700)
                    .create(dir)
                    .with_context(|| format!("creating --scratch {}", dir.display()))?;
            }
            Err(e) => return Err(e).with_context(|| format!("--scratch {}", dir.display())),
            Ok(meta) if meta.file_type().is_symlink() => {
                return Err(refuse("is a symbolic link; give a directory"));
            }
            Ok(meta) if !meta.is_dir() => return Err(refuse("is not a directory")),
            Ok(meta) => {
                let me = tempfile::tempfile()
                    .and_then(|f| f.metadata())
                    .context("finding this process's user")?
                    .uid();
                if meta.uid() != me {
                    return Err(refuse("belongs to another user"));
                }
                if let Some(entry) = std::fs::read_dir(dir)?.next() {
                    return Err(refuse(&format!(
                        "is not empty (it holds {:?}); give a new or an empty directory",
                        entry?.file_name()
                    )));
                }
                std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o700))?;
            }
        }
        Ok(Scratch::Given(dir.to_path_buf()))
    }

    fn path(&self) -> &Path {
        match self {
            Scratch::Temporary(dir) => dir.path(),
            Scratch::Given(dir) => dir,
        }
    }

    /// Removes a run's output directory before the run (a link is removed, never followed).
    fn clear(dir: &Path) -> Result<()> {
        match std::fs::symlink_metadata(dir) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
            Err(e) => Err(e).with_context(|| format!("clearing {}", dir.display())),
            Ok(meta) if meta.is_dir() => {
                std::fs::remove_dir_all(dir).with_context(|| format!("clearing {}", dir.display()))
            }
            Ok(_) => {
                std::fs::remove_file(dir).with_context(|| format!("clearing {}", dir.display()))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    fn mode(p: &Path) -> u32 {
        std::fs::metadata(p).expect("metadata").permissions().mode() & 0o777
    }

    /// Issue 14: the default scratch was `/tmp/qicp-bench-park-<pid>`, reused if it existed.
    #[test]
    fn default_scratch_is_fresh_private_and_unpredictable() {
        let a = Scratch::prepare(None).expect("scratch");
        let b = Scratch::prepare(None).expect("scratch");
        assert_ne!(a.path(), b.path());
        assert_eq!(mode(a.path()), 0o700);
        let name = a.path().file_name().expect("name").to_string_lossy();
        assert!(name.starts_with("qicp-bench-park-"), "{name}");
        assert!(
            !name.contains(&std::process::id().to_string()),
            "predictable: {name}"
        );
        let path = a.path().to_path_buf();
        drop(a);
        assert!(!path.exists(), "a temporary scratch is removed");
    }

    #[test]
    fn given_scratch_is_created_private_or_must_be_empty() {
        let root = tempfile::tempdir().expect("root");
        let new = root.path().join("new");
        let made = Scratch::prepare(Some(&new)).expect("created");
        assert_eq!(mode(made.path()), 0o700);
        drop(made);
        assert!(new.is_dir(), "a given scratch is kept");
        // Empty and open to all: accepted, and closed.
        std::fs::set_permissions(&new, std::fs::Permissions::from_mode(0o777)).expect("chmod");
        Scratch::prepare(Some(&new)).expect("empty is fine");
        assert_eq!(mode(&new), 0o700);
        // Something planted inside: refused.
        std::os::unix::fs::symlink("/etc/passwd", new.join("in-process")).expect("link");
        let err = Scratch::prepare(Some(&new)).expect_err("not empty");
        assert!(err.to_string().contains("not empty"), "{err}");
        // A link to a directory: refused.
        let link = root.path().join("link");
        std::os::unix::fs::symlink(root.path(), &link).expect("link");
        let err = Scratch::prepare(Some(&link)).expect_err("a link");
        assert!(err.to_string().contains("symbolic link"), "{err}");
    }

    #[test]
    fn clearing_a_run_directory_removes_a_link_not_its_target() {
        let root = tempfile::tempdir().expect("root");
        let victim = root.path().join("victim");
        std::fs::create_dir(&victim).expect("victim");
        std::fs::write(victim.join("keep"), "x").expect("file");
        let run = root.path().join("two-process");
        std::os::unix::fs::symlink(&victim, &run).expect("link");
        Scratch::clear(&run).expect("clear");
        assert!(!run.exists() && victim.join("keep").exists());
    }
}
