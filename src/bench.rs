//! `qicp bench …`: user-facing benchmarks that print JSON.
//!
//! `qicp bench index` builds every [`SpatialIndex`] on the same seeded points and times
//!
//! - **build**: inserting all points one by one into an empty index (a rebuild from scratch);
//! - **queries**: one [`SpatialIndex::nearest`] per query point;
//! - **scan insert**: inserting one more 181-point scan into the built index, the incremental
//!   update a mapper does after each matched scan.
//!
//! Each figure is the median over `--reps` repetitions after one untimed warm-up repetition;
//! the repetitions interleave the indexes, so a burst of machine noise hits all of them alike.
//! The warm-up also checks that every index returns bit-identical nearest distances for every
//! query (`agree`).
//!
//! Data, queries and the extra scans are consecutive slices of *one* seeded stream
//! (`data = stream[..N]`, `queries = stream[N..N+M]`, then the scans): for `--layout scans` the
//! queries are thus fresh sweeps from new poses in the *same* building, lying near its surfaces
//! like the points of a scan being matched. (Another seed would also move the posts and tilt
//! the inner walls of the building, so its points would not be near the data's surfaces.)
//! For `--layout uniform` everything is uniform in a [`UNIFORM_SIZE`]-metre square.

use anyhow::{Result, ensure};
use clap::{Args, Subcommand, ValueEnum};
use qicp_core::{BruteForce, KdTree, Point2, QuadTree, SpatialIndex, testdata};
use serde::Serialize;
use std::hint::black_box;
use std::time::{Duration, Instant};

/// Benchmarks.
#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// Spatial indexes: build, incremental scan insertion and nearest-neighbour query times.
    Index(IndexArgs),
    /// The iceoryx2 bridge: one-way latency and throughput against a Unix-domain socket.
    Bridge(crate::bridge_cmd::BridgeBenchArgs),
    /// The bridge's cost on a whole drive: simulate and match in one process, against
    /// `qicp sim --publish` feeding `qicp match --subscribe` (wall times, JSON with --json).
    BridgePark(crate::bridge_cmd::ParkBenchArgs),
}

/// Runs the command.
pub fn run(c: BenchCommand) -> Result<()> {
    match c {
        BenchCommand::Index(a) => {
            let report = index_bench(&a)?;
            if a.json {
                qicp_core::say!("{}", serde_json::to_string(&report)?)?;
            } else {
                qicp_core::output::write_stdout(&report.table())?;
            }
            Ok(())
        }
        BenchCommand::Bridge(a) => crate::bridge_cmd::run_bench(&a),
        BenchCommand::BridgePark(a) => crate::bridge_cmd::run_park_bench(&a),
    }
}

/// Side of the square the `uniform` layout fills (m): about the extent of the `scans` building.
pub const UNIFORM_SIZE: f64 = 50.0;
/// Brute force is timed only up to this many points (it answers a query in O(N)).
pub const BRUTE_MAX_POINTS: usize = 20_000;
/// Beams of one scan (a 180° sweep at 1°), the unit of incremental insertion.
pub const SCAN_BEAMS: usize = 181;
/// Scans inserted (and timed one by one) into each built index per repetition.
pub const SCANS_PER_REP: usize = 5;

/// How the points are laid out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Layout {
    /// Uniform in a square of side [`UNIFORM_SIZE`].
    Uniform,
    /// Laser sweeps of walls and posts ([`testdata::laser_scans`]): the realistic case.
    Scans,
}

/// Arguments of `qicp bench index`.
#[derive(Debug, Clone, Args)]
pub struct IndexArgs {
    /// Points in each index (at most 50,000,000).
    #[arg(long, default_value_t = 100_000)]
    pub points: usize,
    /// Nearest-neighbour queries timed per repetition (at most 50,000,000).
    #[arg(long, default_value_t = 100_000)]
    pub queries: usize,
    /// Seed of the point stream.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Point layout.
    #[arg(long, value_enum, default_value_t = Layout::Scans)]
    pub layout: Layout,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Timed repetitions (the median is reported), after one untimed warm-up (at most 1,000).
    #[arg(long, default_value_t = 5)]
    pub reps: usize,
}

/// Median times of one index.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct IndexTimes {
    /// Building the index from scratch by inserting every point (ms).
    pub build_ms: f64,
    /// `build_ms` per point (ns).
    pub insert_ns_per_point: f64,
    /// One nearest-neighbour query (ns).
    pub query_ns: f64,
}

/// The indexes timed.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Indexes {
    /// [`QuadTree`].
    pub quadtree: IndexTimes,
    /// [`KdTree`].
    pub kdtree: IndexTimes,
    /// [`BruteForce`]; `None` above [`BRUTE_MAX_POINTS`].
    pub brute: Option<IndexTimes>,
}

/// Median time to insert one [`SCAN_BEAMS`]-point scan into an index of `points` points (µs).
#[derive(Debug, Clone, Copy, Serialize)]
pub struct ScanInsert {
    /// Into the [`QuadTree`].
    pub quadtree: f64,
    /// Into the [`KdTree`].
    pub kdtree: f64,
}

/// Result of `qicp bench index`, printed as JSON with `--json`.
#[derive(Debug, Clone, Serialize)]
pub struct IndexReport {
    /// Points in each index.
    pub points: usize,
    /// Queries per repetition.
    pub queries: usize,
    /// Point layout.
    pub layout: Layout,
    /// Seed of the point stream.
    pub seed: u64,
    /// Timed repetitions behind each median.
    pub reps: usize,
    /// Per-index medians.
    pub indexes: Indexes,
    /// Incremental insertion of one scan (µs), to compare with `build_ms`.
    pub scan_insert_us: ScanInsert,
    /// `quadtree.query_ns / kdtree.query_ns`: below 1 when the quad tree answers faster.
    pub query_ratio_quadtree_over_kdtree: f64,
    /// Every index returned the same nearest distance (exact `f64` equality) for every query.
    pub agree: bool,
}

impl IndexReport {
    /// A readable table.
    #[must_use]
    pub fn table(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        let layout = match self.layout {
            Layout::Uniform => "uniform",
            Layout::Scans => "scans",
        };
        let _ = writeln!(
            s,
            "qicp bench index: {} points, {} queries, layout {layout}, seed {}, median of {} reps",
            self.points, self.queries, self.seed, self.reps
        );
        let _ = writeln!(
            s,
            "{:<10} {:>12} {:>16} {:>12} {:>18}",
            "index", "build (ms)", "insert (ns/pt)", "query (ns)", "scan insert (µs)"
        );
        let rows = [
            (
                "quadtree",
                Some(self.indexes.quadtree),
                Some(self.scan_insert_us.quadtree),
            ),
            (
                "kdtree",
                Some(self.indexes.kdtree),
                Some(self.scan_insert_us.kdtree),
            ),
            ("brute", self.indexes.brute, None),
        ];
        for (name, times, scan) in rows {
            match times {
                Some(t) => {
                    let scan = scan.map_or_else(|| "-".to_owned(), |us| format!("{us:.1}"));
                    let _ = writeln!(
                        s,
                        "{name:<10} {:>12.2} {:>16.1} {:>12.1} {scan:>18}",
                        t.build_ms, t.insert_ns_per_point, t.query_ns
                    );
                }
                None => {
                    let _ = writeln!(s, "{name:<10} (skipped above {BRUTE_MAX_POINTS} points)");
                }
            }
        }
        let _ = writeln!(
            s,
            "query time quad tree / kd-tree: {:.3}",
            self.query_ratio_quadtree_over_kdtree
        );
        let _ = writeln!(
            s,
            "one {SCAN_BEAMS}-point scan into the quad tree: {:.1} µs; rebuilding the quad tree: \
             {:.2} ms ({:.0}× more), the kd-tree: {:.2} ms ({:.0}× more)",
            self.scan_insert_us.quadtree,
            self.indexes.quadtree.build_ms,
            self.indexes.quadtree.build_ms * 1e3 / self.scan_insert_us.quadtree,
            self.indexes.kdtree.build_ms,
            self.indexes.kdtree.build_ms * 1e3 / self.scan_insert_us.quadtree,
        );
        let _ = writeln!(
            s,
            "all indexes agree on every nearest distance: {}",
            if self.agree { "yes" } else { "NO" }
        );
        s
    }
}

/// The points of one run: the index contents, the queries and the scans inserted afterwards.
struct Workload {
    data: Vec<Point2<f64>>,
    queries: Vec<Point2<f64>>,
    scans: Vec<Vec<Point2<f64>>>,
}

impl Workload {
    /// Consecutive slices of one seeded stream (see the module documentation for why).
    fn new(a: &IndexArgs) -> Self {
        let scans = SCANS_PER_REP;
        let total = a.points + a.queries + scans * SCAN_BEAMS;
        let all = match a.layout {
            Layout::Uniform => testdata::uniform(total, UNIFORM_SIZE, a.seed),
            Layout::Scans => testdata::laser_scans(total, a.seed),
        };
        let (data, rest) = all.split_at(a.points);
        let (queries, rest) = rest.split_at(a.queries);
        Self {
            data: data.to_vec(),
            queries: queries.to_vec(),
            scans: rest.chunks(SCAN_BEAMS).map(<[_]>::to_vec).collect(),
        }
    }
}

/// Times of one repetition of one index.
#[derive(Debug, Default)]
struct Samples {
    build: Vec<Duration>,
    query: Vec<Duration>,
    scan: Vec<Duration>,
}

impl Samples {
    fn times(&self, w: &Workload) -> IndexTimes {
        let build = median(&self.build);
        IndexTimes {
            build_ms: build * 1e3,
            insert_ns_per_point: build * 1e9 / w.data.len() as f64,
            query_ns: median(&self.query) * 1e9 / w.queries.len() as f64,
        }
    }

    fn scan_us(&self) -> f64 {
        median(&self.scan) * 1e6
    }
}

/// Median in seconds; NaN for none.
fn median(d: &[Duration]) -> f64 {
    let secs: Vec<f64> = d.iter().map(Duration::as_secs_f64).collect();
    crate::eval::stats::median(&secs).unwrap_or(f64::NAN)
}

fn build<I: SpatialIndex + Default>(points: &[Point2<f64>]) -> Result<I> {
    let mut index = I::default();
    for p in points {
        index.insert(black_box(*p))?;
    }
    Ok(index)
}

/// The untimed warm-up: builds the index and returns every query's nearest distance.
fn nearest_dists<I: SpatialIndex + Default>(w: &Workload) -> Result<Vec<Option<f64>>> {
    let index: I = build(&w.data)?;
    Ok(w.queries
        .iter()
        .map(|q| index.nearest(q).map(|n| n.dist_sq))
        .collect())
}

/// One timed repetition: build, query, then insert the extra scans one at a time.
fn one_rep<I: SpatialIndex + Default>(w: &Workload, s: &mut Samples) -> Result<()> {
    let t = Instant::now();
    let mut index: I = build(&w.data)?;
    s.build.push(t.elapsed());

    let t = Instant::now();
    let mut sum = 0.0;
    for q in &w.queries {
        if let Some(n) = index.nearest(black_box(q)) {
            sum += n.dist_sq;
        }
    }
    black_box(sum);
    s.query.push(t.elapsed());

    for scan in &w.scans {
        let t = Instant::now();
        for p in scan {
            index.insert(black_box(*p))?;
        }
        s.scan.push(t.elapsed());
    }
    black_box(&index);
    Ok(())
}

/// Most points (and queries) `qicp bench index` takes: 50 million points are 800 MB.
pub const MAX_BENCH_POINTS: usize = 50_000_000;
/// Most timed repetitions of `qicp bench index`.
pub const MAX_BENCH_REPS: usize = 1_000;

/// Runs `qicp bench index` and returns its report.
pub fn index_bench(a: &IndexArgs) -> Result<IndexReport> {
    ensure!(
        (1..=MAX_BENCH_POINTS).contains(&a.points),
        "--points must be 1 to {MAX_BENCH_POINTS}"
    );
    ensure!(
        (1..=MAX_BENCH_POINTS).contains(&a.queries),
        "--queries must be 1 to {MAX_BENCH_POINTS}"
    );
    ensure!(
        (1..=MAX_BENCH_REPS).contains(&a.reps),
        "--reps must be 1 to {MAX_BENCH_REPS}"
    );
    let w = Workload::new(a);
    let with_brute = a.points <= BRUTE_MAX_POINTS;

    // Warm-up, and the correctness check.
    let quad = nearest_dists::<QuadTree>(&w)?;
    let kd = nearest_dists::<KdTree>(&w)?;
    let mut agree = quad == kd;
    if with_brute {
        agree &= nearest_dists::<BruteForce>(&w)? == quad;
    }

    let (mut quad, mut kd, mut brute) =
        (Samples::default(), Samples::default(), Samples::default());
    for _ in 0..a.reps {
        one_rep::<QuadTree>(&w, &mut quad)?;
        one_rep::<KdTree>(&w, &mut kd)?;
        if with_brute {
            one_rep::<BruteForce>(&w, &mut brute)?;
        }
    }

    let indexes = Indexes {
        quadtree: quad.times(&w),
        kdtree: kd.times(&w),
        brute: with_brute.then(|| brute.times(&w)),
    };
    Ok(IndexReport {
        points: a.points,
        queries: a.queries,
        layout: a.layout,
        seed: a.seed,
        reps: a.reps,
        query_ratio_quadtree_over_kdtree: indexes.quadtree.query_ns / indexes.kdtree.query_ns,
        scan_insert_us: ScanInsert {
            quadtree: quad.scan_us(),
            kdtree: kd.scan_us(),
        },
        indexes,
        agree,
    })
}
