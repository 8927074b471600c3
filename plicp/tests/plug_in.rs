//! PL-ICP as a plug-in: registered from outside the framework, it is configured, checked,
//! composed with every index and run like the built-in matchers.

use qicp_core::testdata::SyntheticWorld;
use qicp_core::{Pose2, Record};
use qicp_matchers::{ConfigError, Registry};

fn registry() -> Registry {
    let mut r = Registry::builtin();
    qicp_plicp::register(&mut r);
    r
}

#[test]
fn registering_adds_every_composed_name() {
    let names = registry().names();
    for name in ["plicp", "q-plicp", "kd-plicp", "bf-plicp", "q-wsm"] {
        assert!(names.iter().any(|n| n == name), "{name} in {names:?}");
    }
    assert!(
        !Registry::builtin()
            .names()
            .iter()
            .any(|n| n.contains("plicp"))
    );
}

#[test]
fn its_section_is_checked_like_a_built_in_one() {
    let r = registry();
    let c = r
        .parse("[matcher]\nalgorithm = \"plicp\"\n[matcher.plicp]\nsigma = 0.03\n")
        .expect("valid");
    assert_eq!(c.kind(), "q-plicp");
    assert_eq!(c.params::<qicp_plicp::PlIcpParams>().unwrap().sigma, 0.03);
    assert!(c.to_toml().contains("[matcher.plicp]"));
    // Its own iteration defaults, overridable key by key.
    assert_eq!(c.icp.max_dist_end, 0.1);
    let e = r
        .parse("[matcher]\nkind = \"plicp\"\n[matcher.plicp]\nsigm = 0.03\n")
        .unwrap_err();
    assert!(e.to_string().contains("matcher.plicp.sigm"), "{e}");
    let e = r
        .parse("[matcher]\nkind = \"plicp\"\n[matcher.plicp]\ntangent_weight = 2.0\n")
        .unwrap_err();
    assert!(
        matches!(e, ConfigError::Invalid { .. }) && e.to_string().contains("tangent_weight"),
        "{e}"
    );
    let e = r
        .parse("[matcher]\nkind = \"plicp\"\n[matcher.wsm]\nsigma_range = 0.02\n")
        .unwrap_err();
    assert!(matches!(e, ConfigError::Unused { .. }), "{e}");
    // The sweep perturbs its steering parameters too.
    let keys = c.steering_parameters();
    assert!(keys.iter().any(|k| k == "matcher.plicp.sigma"), "{keys:?}");
    let scaled = c.scaled("matcher.plicp.sigma", 1.4).unwrap();
    assert!((scaled.parameter("matcher.plicp.sigma").unwrap() - 0.042).abs() < 1e-12);
}

/// The first gate is set per reference (`gate_sigmas` against a scan, `map_gate_sigmas`
/// against a map): the sweep perturbs each only where it acts, so no variant repeats the
/// default run.
#[test]
fn each_first_gate_is_swept_only_on_the_reference_it_acts_on() {
    let r = registry();
    let config = |text: &str| r.parse(text).expect("valid");
    let plicp = config("[matcher]\nkind = \"plicp\"\n[matcher.plicp]\nmap_gate_sigmas = 2\n");
    let q_plicp = config("[matcher]\nkind = \"q-plicp\"\n[matcher.plicp]\nmap_gate_sigmas = 2\n");
    let swept = |c: &qicp_matchers::MatcherConfig, key: &str| {
        c.steering_parameters()
            .iter()
            .any(|k| k == &format!("matcher.plicp.{key}"))
    };
    assert!(swept(&plicp, "gate_sigmas") && !swept(&plicp, "map_gate_sigmas"));
    assert!(!swept(&q_plicp, "gate_sigmas") && swept(&q_plicp, "map_gate_sigmas"));
    assert!(
        swept(&plicp, "sigma") && swept(&q_plicp, "sigma"),
        "the others act on both"
    );
}

/// Record `k` of a drive through the room: its scan seen from `truth` (1 s apart), with
/// `odometry` as the wheels read it.
fn room_record(truth: Pose2, k: usize, odometry: Pose2) -> Record {
    let mut scan = SyntheticWorld::room().scan(&truth, 0.005, k as u64 + 1);
    scan.timestamp = k as f64;
    Record {
        scan,
        odometry,
        truth: Some(truth),
        laser_offset: Pose2::IDENTITY,
    }
}

fn drive(kind: &str) -> Vec<Pose2> {
    let mut pipeline = registry()
        .config(kind)
        .expect("a registered kind")
        .build()
        .expect("a valid default config");
    let mut out = Vec::new();
    for k in 0..40 {
        let truth = Pose2::new(
            -2.5 + 0.1 * k as f64,
            -0.8 + 0.03 * k as f64,
            0.025 * k as f64,
        );
        // Odometry drifting by 1 cm and 0.3° a scan.
        let odometry = truth * Pose2::new(0.01 * k as f64, 0.0, (0.3 * k as f64).to_radians());
        let e = pipeline.process(&room_record(truth, k, odometry));
        assert!(
            e.pose.distance(&truth) < 0.03,
            "{kind}, scan {k}: {:.3} m off",
            e.pose.distance(&truth)
        );
        assert!(
            qicp_core::normalize_angle(e.pose.theta - truth.theta).abs() < 0.01,
            "{kind}, scan {k}"
        );
        out.push(e.pose);
    }
    out
}

#[test]
fn plicp_recovers_the_drive_where_odometry_drifts() {
    drive("plicp");
}

/// Identical answers across indexes: the boosted forms over the quad tree, the kd-tree and
/// the brute-force oracle give the same poses.
#[test]
fn boosted_plicp_is_the_same_over_every_index() {
    let q = drive("q-plicp");
    assert_eq!(q, drive("kd-plicp"));
    assert_eq!(q, drive("bf-plicp"));
}

/// Map points after each of ten loops of the room (radius 2 m, 40 scans a loop, odometry
/// exact), with the config parsed from `toml`.
fn ten_loops(toml: &str) -> Vec<usize> {
    let mut pipeline = registry()
        .parse(toml)
        .expect("a valid config")
        .build()
        .expect("builds");
    let mut sizes = Vec::new();
    for k in 0..400 {
        let a = std::f64::consts::TAU * (k % 40) as f64 / 40.0;
        let truth = Pose2::new(
            0.5 + 2.0 * a.cos(),
            -0.5 + 2.0 * a.sin(),
            a + std::f64::consts::FRAC_PI_2,
        );
        let e = pipeline.process(&room_record(truth, k, truth));
        assert!(e.pose.distance(&truth) < 0.05, "step {k}: {e:?}");
        if k % 40 == 39 {
            sizes.push(pipeline.reference_points().len());
        }
    }
    sizes
}

#[test]
fn q_plicp_gates_its_map_by_novelty_by_default_and_stops_growing_over_ten_loops() {
    let mut effective = registry().config("q-plicp").expect("registered");
    effective.fill_defaults();
    assert_eq!(effective.relevance.min_novelty, Some(0.05));
    let gated = ten_loops("[matcher]\nkind = \"q-plicp\"\n");
    let every = ten_loops("[matcher]\nkind = \"q-plicp\"\n[matcher.relevance]\nmin_novelty = 0\n");
    println!("q-plicp map after each loop: gated {gated:?}, every relevant scan {every:?}");
    // The loops after the first add nothing the map lacks; without the gate each adds the
    // points its noise puts off the surfaces held.
    assert!(
        gated[9] as f64 <= 1.02 * gated[0] as f64,
        "gated: {gated:?}"
    );
    assert!(
        every[9] as f64 > 1.3 * every[0] as f64,
        "every relevant scan: {every:?}"
    );
}
