//! The TOML registry: every kind builds from its defaults, effective configs round-trip, and
//! bad input is refused with a message that names the key.

use qicp_matchers::{ConfigError, MatcherConfig, MatcherKind, Registry, WsmParams};

fn err(text: &str) -> String {
    MatcherConfig::from_toml(text)
        .expect_err("must be refused")
        .to_string()
}

#[test]
fn every_kind_builds_and_round_trips() {
    for kind in MatcherKind::ALL {
        let config = MatcherConfig::defaults(kind);
        let pipeline = config.build().expect("defaults build");
        assert_eq!(pipeline.kind(), kind.name());
        let again = MatcherConfig::from_toml(&config.to_toml()).expect("effective config parses");
        assert_eq!(again, config, "{kind}: the effective config round-trips");
    }
}

#[test]
fn kind_and_parameters_from_toml() {
    let c = MatcherConfig::from_toml(
        "[matcher]\nkind = \"q-wsm\"\n[matcher.icp]\nmax_iterations = 7\n[matcher.wsm]\nsigma_range = 0.02\n[matcher.relevance]\ntau_max = 0.5\n",
    )
    .unwrap();
    assert_eq!(c.kind(), MatcherKind::QWsm.name());
    assert_eq!(c.icp.max_iterations, 7);
    assert_eq!(c.laser.sigma_range, 0.02);
    assert_eq!(c.relevance.tau_max, 0.5);
}

/// Laser noise is one sensor parameter: `[matcher.laser]` for every algorithm, read from the
/// WSM section of configs written before it with the same meaning, and given once.
#[test]
fn laser_noise_is_one_sensor_parameter_and_old_wsm_configs_keep_their_meaning() {
    let new = MatcherConfig::from_toml(
        "[matcher]\nkind = \"q-wsm\"\n[matcher.laser]\nsigma_range = 0.02\nsigma_bearing = 0.002\n",
    )
    .unwrap();
    let old = MatcherConfig::from_toml(
        "[matcher]\nkind = \"q-wsm\"\n[matcher.wsm]\nsigma_range = 0.02\nsigma_bearing = 0.002\n",
    )
    .unwrap();
    assert_eq!(new, old);
    assert_eq!(new.laser.sigma_bearing, 0.002);
    // WSM's map resolution defaults to the laser's range noise.
    assert_eq!(new.relevance.map_resolution, Some(0.02));
    let toml = new.to_toml();
    assert!(toml.contains("[matcher.laser]"), "{toml}");
    assert_eq!(MatcherConfig::from_toml(&toml).unwrap(), new);
    // Every algorithm takes it; only the ones weighing by it have it swept.
    let idc = MatcherConfig::from_toml(
        "[matcher]\nkind = \"q-idc\"\n[matcher.laser]\nsigma_range = 0.03\n",
    )
    .unwrap();
    assert_eq!(idc.laser.sigma_range, 0.03);
    assert!(
        !idc.steering_parameters()
            .iter()
            .any(|k| k.contains("laser"))
    );
    assert!(
        new.steering_parameters()
            .contains(&"matcher.laser.sigma_range".to_string())
    );
    let scaled = new.scaled("matcher.laser.sigma_range", 1.4).unwrap();
    assert!((scaled.laser.sigma_range - 0.028).abs() < 1e-12);
    let both = MatcherConfig::from_toml(
        "[matcher]\nkind = \"wsm\"\n[matcher.wsm]\nsigma_range = 0.02\n[matcher.laser]\nsigma_range = 0.02\n",
    )
    .unwrap_err()
    .to_string();
    assert!(
        both.contains("matcher.wsm.sigma_range") && both.contains("once"),
        "{both}"
    );
}

#[test]
fn unknown_keys_are_refused_by_name() {
    assert!(err("[matcher]\nkind = \"wsm\"\nfoo = 1\n").contains("foo"));
    assert!(
        err("[matcher]\nkind = \"wsm\"\n[matcher.icp]\nmax_iteration = 3\n")
            .contains("max_iteration")
    );
    assert!(err("[matcher]\nkind = \"wsm\"\n[matcher.wsm]\nsigma = 3\n").contains("sigma"));
    assert!(err("[matchers]\nkind = \"wsm\"\n").contains("matchers"));
}

#[test]
fn unknown_kinds_are_refused() {
    let e = err("[matcher]\nkind = \"icp\"\n");
    assert!(e.contains("icp") && e.contains("kind"), "{e}");
    assert!("q-icp".parse::<MatcherKind>().is_err());
}

#[test]
fn out_of_range_values_name_the_key() {
    let cases = [
        (
            "[matcher.icp]\nmax_iterations = 0",
            "matcher.icp.max_iterations",
        ),
        (
            "[matcher.icp]\nmax_dist_start = -1.0",
            "matcher.icp.max_dist_start",
        ),
        (
            "[matcher.relevance]\nfree_space_margin = -0.1",
            "matcher.relevance.free_space_margin",
        ),
        (
            "[matcher.icp]\nmax_dist_end = 5.0",
            "matcher.icp.max_dist_end",
        ),
        ("[matcher.icp]\nshrink = 1.5", "matcher.icp.shrink"),
        ("[matcher.icp]\nshrink = 1", "matcher.icp.shrink"),
        (
            "[matcher.wsm]\nsigma_range = 0.0",
            "matcher.wsm.sigma_range",
        ),
        (
            "[matcher.laser]\nsigma_bearing = -1.0",
            "matcher.laser.sigma_bearing",
        ),
        (
            "[matcher.wsm]\nsigma_slide = nan",
            "matcher.wsm.sigma_slide",
        ),
        (
            "[matcher.relevance]\ntau_max = -0.1",
            "matcher.relevance.tau_max",
        ),
        (
            "[matcher.motion]\nsigma_xy_min = 0.0",
            "matcher.motion.sigma_xy_min",
        ),
    ];
    for (section, key) in cases {
        let text = format!("[matcher]\nkind = \"q-wsm\"\n{section}\n");
        let e = MatcherConfig::from_toml(&text).expect_err(section);
        assert!(matches!(e, ConfigError::Invalid { .. }), "{section}: {e}");
        assert!(e.to_string().contains(key), "{section}: {e}");
    }
}

#[test]
fn sections_the_kind_does_not_use_are_refused() {
    let e = err("[matcher]\nkind = \"idc\"\n[matcher.wsm]\nsigma_range = 0.02\n");
    assert!(e.contains("matcher.wsm") && e.contains("idc"), "{e}");
    let e = err("[matcher]\nkind = \"q-wsm\"\n[matcher.idc]\nwindow_start_deg = 10.0\n");
    assert!(e.contains("matcher.idc"), "{e}");
}

#[test]
fn idc_values_name_the_key() {
    for (section, key) in [
        (
            "[matcher.idc]\ngate_sigmas = -1.0",
            "matcher.idc.gate_sigmas",
        ),
        (
            "[matcher.idc]\nwindow_sigmas = nan",
            "matcher.idc.window_sigmas",
        ),
    ] {
        let text = format!("[matcher]\nkind = \"q-idc\"\n{section}\n");
        let e = MatcherConfig::from_toml(&text).expect_err(section);
        assert!(e.to_string().contains(key), "{section}: {e}");
    }
}

/// IDC's first gate follows the odometry prior: a tight prior skips the wide gates (but keeps
/// one stage before the last, where the range rule runs), a loose one or none starts wide.
#[test]
fn idc_first_gate_follows_the_prior() {
    use qicp_core::Matrix3;
    use qicp_matchers::{IcpParams, IdcParams};
    let icp = IcpParams::default(); // gates 1.0, 0.5, 0.25, 0.2
    let idc = IdcParams::default(); // 5 σ
    let information =
        |sigma: f64| Matrix3::from_diagonal(&[1.0, 1.0, 1.0].into()) / (sigma * sigma);
    assert_eq!(icp.last_level(), 3);
    assert_eq!(idc.first_level(&icp, None), 0);
    assert_eq!(idc.first_level(&icp, Some(&information(0.5))), 0);
    assert_eq!(idc.first_level(&icp, Some(&information(0.09))), 1); // 0.45 m ≤ 0.5 m
    assert_eq!(idc.first_level(&icp, Some(&information(0.01))), 2); // never the last level
    let off = IdcParams {
        gate_sigmas: 0.0,
        ..idc
    };
    assert_eq!(off.first_level(&icp, Some(&information(0.01))), 0);
}

#[test]
fn steering_parameters_scale_one_at_a_time() {
    for kind in MatcherKind::ALL {
        let base = MatcherConfig::defaults(kind);
        let keys = base.steering_parameters();
        assert!(keys.contains(&"matcher.icp.max_dist_start".to_string()));
        assert!(keys.contains(&"matcher.relevance.tau_max".to_string()));
        for key in &keys {
            let v = base
                .parameter(key)
                .expect("a steering parameter is a number");
            assert!(
                v != 0.0,
                "{kind}: {key} is 0 and scaling it would change nothing"
            );
            let scaled = base.scaled(key, 1.4).expect("×1.4 is valid");
            // Integers are rounded to the nearest whole number (2 confirmations × 1.4 → 3).
            let got = scaled.parameter(key).unwrap();
            assert!(
                (got - v * 1.4).abs() < 1e-12 || (v.fract() == 0.0 && got == (v * 1.4).round()),
                "{kind}: {key} {v} × 1.4 gave {got}"
            );
            // Nothing else moved.
            for other in keys.iter().filter(|k| *k != key) {
                assert_eq!(scaled.parameter(other), base.parameter(other), "{other}");
            }
        }
    }
    // A map's own parameters are swept for map matchers only: scan to scan they change
    // nothing.
    for key in [
        "matcher.relevance.map_resolution",
        "matcher.relevance.surface_band_sigmas",
    ] {
        let has = |kind| {
            MatcherConfig::defaults(kind)
                .steering_parameters()
                .contains(&key.to_string())
        };
        assert!(has(MatcherKind::QWsm) && has(MatcherKind::KdWsm), "{key}");
        assert!(!has(MatcherKind::Wsm) && !has(MatcherKind::Idc), "{key}");
    }
    // Odometry's veto guards a map only, but its test also tells a stalled reading scan to
    // scan (`motion.stall_restart`).
    let chi2 = "matcher.validation.max_odometry_chi2".to_string();
    assert!(
        MatcherConfig::defaults(MatcherKind::Wsm)
            .steering_parameters()
            .contains(&chi2)
    );
    // A parameter that only serves one that is off is not swept; it is once that one is on.
    let mut gated = MatcherConfig::defaults(MatcherKind::QWsm);
    gated.relevance.min_novelty = Some(0.0);
    let novelty = "matcher.relevance.novelty_distance".to_string();
    assert!(!gated.steering_parameters().contains(&novelty));
    gated.relevance.min_novelty = Some(0.02);
    assert!(gated.steering_parameters().contains(&novelty));
    let err = MatcherConfig::defaults(MatcherKind::QWsm)
        .scaled("matcher.icp.nope", 2.0)
        .unwrap_err();
    assert!(err.to_string().contains("matcher.icp.nope"));
}

/// The cell cap is on by default at two surfaces' samples per cell, at the map's own spacing,
/// is swept like every density bound, and is off where the map keeps every point (Alg. 1).
#[test]
fn the_default_cell_cap_is_two_surfaces_at_the_maps_spacing() {
    let cap = |c: &MatcherConfig| c.parameter("matcher.relevance.max_cell_points");
    for (kind, points) in [
        (MatcherKind::QWsm, 29.0),
        (MatcherKind::KdWsm, 29.0),
        (MatcherKind::QIdc, 15.0),
    ] {
        let c = MatcherConfig::defaults(kind);
        assert_eq!(cap(&c), Some(points), "{kind}");
        let keys = c.steering_parameters();
        for key in ["max_cell_points", "cell_size"] {
            let key = format!("matcher.relevance.{key}");
            assert!(keys.contains(&key), "{kind}: {key} is not swept");
        }
        // At a finer spacing, a finer wall: the cap follows unless it is given.
        let parse = |relevance: &str| {
            MatcherConfig::from_toml(&format!(
                "[matcher]\nkind = \"{kind}\"\n[matcher.relevance]\n{relevance}\n"
            ))
            .expect("parses")
        };
        assert_eq!(cap(&parse("map_resolution = 0.005")), Some(57.0), "{kind}");
        let given = parse("map_resolution = 0.005\nmax_cell_points = 12");
        assert_eq!(cap(&given), Some(12.0), "{kind}");
        let plain = parse("map_resolution = 0.0");
        assert_eq!(cap(&plain), Some(0.0), "{kind}");
        assert!(
            !plain
                .steering_parameters()
                .contains(&"matcher.relevance.cell_size".to_string()),
            "{kind}: the cell's size serves no cap"
        );
    }
    assert_eq!(qicp_matchers::pipeline::two_surfaces_cap(0.1, f64::NAN), 0);
    assert_eq!(
        qicp_matchers::pipeline::two_surfaces_cap(1e3, 1e-300),
        u32::MAX
    );
}

/// A check switched off leaves its parameters inert: sweeping them would rerun the default and
/// pull the median ratio towards 1 (a review of the sweep found `revisit.*` variants run with
/// re-anchoring off).
#[test]
fn a_switched_off_check_leaves_its_parameters_out_of_the_sweep() {
    let swept = |c: &MatcherConfig, prefix: &str| {
        c.steering_parameters()
            .iter()
            .filter(|k| k.starts_with(prefix))
            .count()
    };
    let on = MatcherConfig::defaults(MatcherKind::QWsm);
    for prefix in [
        "matcher.validation.",
        "matcher.correlative.",
        "matcher.revisit.",
        "matcher.motion.sigma_",
    ] {
        assert!(swept(&on, prefix) > 0, "{prefix}");
    }
    let mut no_revisit = on.clone();
    no_revisit.revisit.enabled = false;
    assert_eq!(swept(&no_revisit, "matcher.revisit."), 0);
    assert_eq!(
        swept(&no_revisit, "matcher.validation."),
        swept(&on, "matcher.validation.")
    );
    let mut no_search = on.clone();
    no_search.validation.search = false;
    assert_eq!(swept(&no_search, "matcher.correlative."), 0);
    assert!(swept(&no_search, "matcher.validation.") > 0);
    let mut unchecked = on.clone();
    unchecked.validation.enabled = false;
    for prefix in [
        "matcher.validation.",
        "matcher.correlative.",
        "matcher.revisit.",
    ] {
        assert_eq!(swept(&unchecked, prefix), 0, "{prefix}");
    }
    assert!(
        !no_search
            .steering_parameters()
            .iter()
            .any(|k| k.ends_with("max_pair_drop") || k.ends_with("max_residual_ratio"))
    );
    let mut no_prior = on.clone();
    no_prior.motion.enabled = false;
    assert_eq!(swept(&no_prior, "matcher.motion.sigma_"), 0);
    for key in ["max_odometry_chi2", "point_evidence"] {
        assert!(
            swept(&on, &format!("matcher.validation.{key}")) > 0,
            "{key}"
        );
        assert_eq!(
            swept(&no_prior, &format!("matcher.validation.{key}")),
            0,
            "{key}"
        );
    }
    let mut no_veto = on.clone();
    no_veto.validation.max_odometry_chi2 = 0.0;
    assert_eq!(swept(&no_veto, "matcher.validation.point_evidence"), 0);
    // The rest of the sweep stays as it was.
    assert!(
        unchecked
            .steering_parameters()
            .contains(&"matcher.icp.max_dist_start".to_string())
    );
}

/// The axes compose to the presets: `kind = "q-wsm"` and `algorithm = "wsm"` (with the
/// default reference and index) are one config, and so are the other five.
#[test]
fn presets_are_compositions_of_the_axes() {
    for (kind, algorithm, reference, index) in [
        ("idc", "idc", "scan", "quadtree"),
        ("wsm", "wsm", "scan", "quadtree"),
        ("q-idc", "idc", "map", "quadtree"),
        ("q-wsm", "wsm", "map", "quadtree"),
        ("kd-idc", "idc", "map", "kdtree"),
        ("kd-wsm", "wsm", "map", "kdtree"),
    ] {
        let preset = MatcherConfig::from_toml(&format!("[matcher]\nkind = \"{kind}\"\n")).unwrap();
        let axes = MatcherConfig::from_toml(&format!(
            "[matcher]\nalgorithm = \"{algorithm}\"\nreference = \"{reference}\"\nindex = \"{index}\"\n"
        ))
        .unwrap();
        assert_eq!(preset, axes, "{kind}");
        assert_eq!(axes.kind(), kind);
    }
    let short = MatcherConfig::from_toml("[matcher]\nalgorithm = \"wsm\"\n").unwrap();
    assert_eq!(
        short.kind(),
        "q-wsm",
        "the map and the quad tree are the defaults"
    );
}

#[test]
fn axes_that_do_not_resolve_are_refused_by_name() {
    let e = err("[matcher]\nalgorithm = \"plicp\"\n");
    assert!(
        e.contains("matcher.algorithm") && e.contains("plicp"),
        "{e}"
    );
    let e = err("[matcher]\nalgorithm = \"wsm\"\nindex = \"octree\"\n");
    assert!(e.contains("matcher.index") && e.contains("kdtree"), "{e}");
    let e = err("[matcher]\nalgorithm = \"wsm\"\nreference = \"graph\"\n");
    assert!(e.contains("matcher.reference"), "{e}");
    let e = err("[matcher]\nkind = \"q-wsm\"\nalgorithm = \"wsm\"\n");
    assert!(e.contains("not both"), "{e}");
    let e = err("[matcher]\nkind = \"q-wsm\"\nindex = \"kdtree\"\n");
    assert!(e.contains("matcher.kind"), "{e}");
    let e = err("[matcher]\n");
    assert!(e.contains("q-wsm"), "a missing kind lists the names: {e}");
}

/// Every registered index composes with every algorithm: the brute-force oracle, registered
/// through the run-time path ([`qicp_matchers::AnyIndex`]), is `bf-wsm`.
#[test]
fn every_algorithm_composes_with_every_index() {
    let registry = Registry::builtin();
    let names = registry.names();
    for name in [
        "idc", "wsm", "q-idc", "q-wsm", "kd-idc", "kd-wsm", "bf-idc", "bf-wsm",
    ] {
        assert!(names.iter().any(|n| n == name), "{name} in {names:?}");
        let config = registry.config(name).unwrap();
        assert_eq!(config.build().unwrap().kind(), name);
    }
    // Scan to scan over another index: the name composes and resolves back.
    let c = MatcherConfig::from_toml(
        "[matcher]\nalgorithm = \"wsm\"\nreference = \"scan\"\nindex = \"kdtree\"\n",
    )
    .unwrap();
    assert_eq!(c.kind(), "wsm@kdtree");
    assert_eq!(registry.config("wsm@kdtree").unwrap(), c);
}

/// The declared ranges are what the checks enforce: each parameter's description names the
/// range the error message gives.
#[test]
fn declared_parameters_are_checked_generically() {
    let registry = Registry::builtin();
    for algorithm in registry.algorithm_names() {
        let (_, params) = registry.parameters(algorithm).unwrap();
        assert!(!params.is_empty());
        for p in params {
            let bad = match p.range {
                qicp_matchers::Range::Flag => continue,
                qicp_matchers::Range::Closed(lo, _) | qicp_matchers::Range::Open(lo, _) => lo - 1.0,
                _ => -1.0,
            };
            let text = format!(
                "[matcher]\nalgorithm = \"{algorithm}\"\n[matcher.{algorithm}]\n{} = {bad:?}\n",
                p.key
            );
            let e = err(&text);
            assert!(e.contains(&format!("matcher.{algorithm}.{}", p.key)), "{e}");
        }
    }
}

/// One set of defaults: each preset built with the typed constructors and from the registry
/// gives the same poses, bit for bit, on a synthetic drive.
#[test]
fn typed_constructors_and_the_registry_build_the_same_matchers() {
    use qicp_core::testdata::SyntheticWorld;
    use qicp_core::{KdTree, LaserNoise, MutualNearest, Pose2, QuadTree, Record};
    use qicp_matchers::{
        IcpParams, Idc, IdcParams, KdIdc, KdWsm, Odometry, Pipeline, Policy, QIdc, QWsm, Relevance,
        Wsm,
    };
    let (icp, idc, wsm) = (
        IcpParams::default(),
        IdcParams::default(),
        WsmParams::default(),
    );
    let (map, scan) = (
        Policy::Boosted(Relevance::default()),
        Policy::Incremental(Relevance::default()),
    );
    let noise = LaserNoise::default();
    let typed: Vec<(&str, Box<dyn Odometry>)> = vec![
        (
            "idc",
            Box::new(Pipeline::new(
                "idc",
                Idc::<MutualNearest<QuadTree>>::new(icp, idc),
                QuadTree::default(),
                scan,
                noise,
            )),
        ),
        (
            "wsm",
            Box::new(Pipeline::new(
                "wsm",
                Wsm::<MutualNearest<QuadTree>>::new(icp, wsm),
                QuadTree::default(),
                scan,
                noise,
            )),
        ),
        (
            "q-idc",
            Box::new(QIdc::new(
                "q-idc",
                Idc::new(icp, idc),
                QuadTree::default(),
                map,
                noise,
            )),
        ),
        (
            "q-wsm",
            Box::new(QWsm::new(
                "q-wsm",
                Wsm::new(icp, wsm),
                QuadTree::default(),
                map,
                noise,
            )),
        ),
        (
            "kd-idc",
            Box::new(KdIdc::new(
                "kd-idc",
                Idc::new(icp, idc),
                KdTree::default(),
                map,
                noise,
            )),
        ),
        (
            "kd-wsm",
            Box::new(KdWsm::new(
                "kd-wsm",
                Wsm::new(icp, wsm),
                KdTree::default(),
                map,
                noise,
            )),
        ),
    ];
    let world = SyntheticWorld::room();
    for (name, mut typed) in typed {
        let mut built = Registry::builtin().config(name).unwrap().build().unwrap();
        for k in 0..30 {
            let truth = Pose2::new(
                -2.0 + 0.1 * k as f64,
                -0.5 + 0.02 * k as f64,
                0.03 * k as f64,
            );
            let mut s = world.scan(&truth, 0.005, k as u64 + 1);
            s.timestamp = k as f64;
            let record = Record {
                scan: s,
                // Odometry 5 % long and drifting in heading: the prior matters.
                odometry: Pose2::new(truth.x * 1.05, truth.y, truth.theta * 1.02),
                truth: Some(truth),
                laser_offset: Pose2::IDENTITY,
            };
            let (a, b) = (typed.process(&record), built.process(&record));
            assert_eq!(a.pose, b.pose, "{name}, scan {k}");
            assert_eq!(a.inserted, b.inserted, "{name}, scan {k}");
        }
        assert_eq!(typed.reference_points(), built.reference_points(), "{name}");
        // A scan of the room holds about 170 points: a map holds more than one.
        let least = if name.contains('-') { 300 } else { 50 };
        assert!(
            typed.reference_points().len() > least,
            "{name}: the reference holds scans"
        );
    }
}

/// A value of the wrong type used to be reported for its whole section (`matcher.icp:
/// invalid type: string "x", expected u32`): the key at fault is named.
#[test]
fn values_of_the_wrong_type_name_their_key() {
    for (text, key) in [
        (
            "[matcher.icp]\nmax_iterations = \"x\"\n",
            "matcher.icp.max_iterations",
        ),
        (
            "[matcher.relevance]\nwindow_scans = -1\n",
            "matcher.relevance.window_scans",
        ),
        (
            "[matcher.wsm]\nsigma_slide = \"a\"\n",
            "matcher.wsm.sigma_slide",
        ),
        (
            "[matcher.laser]\nsigma_range = true\n",
            "matcher.laser.sigma_range",
        ),
        (
            "[matcher.motion]\nsigma_xy_per_m = [1]\n",
            "matcher.motion.sigma_xy_per_m",
        ),
    ] {
        let e = err(&format!("[matcher]\nkind = \"q-wsm\"\n{text}"));
        assert!(e.contains(&format!("`{key}`")), "{key} not named: {e}");
    }
}

/// An index registered at run time is reached through `Box<dyn AnyIndex>`, which passes its
/// removals and revisions on: a map carves a wrong match's wall out of it in place, as out of
/// the index itself (before, the box refused removal and the map rebuilt the index, renumbering
/// every point), and the correspondence rules can keep their searches between scans.
#[test]
fn a_registered_index_removes_in_place_and_counts_its_revisions() {
    use qicp_core::testdata::SyntheticWorld;
    use qicp_core::{BruteForce, Merge, Point2, Pose2, Reference, SpatialIndex};
    use qicp_matchers::AnyIndex;

    fn room<I: SpatialIndex>(index: I) -> Reference<I> {
        let world = SyntheticWorld::room();
        let carving = Merge {
            free_space_margin: 0.1,
            ..Merge::spacing(0.01)
        };
        let mut map = Reference::new(index);
        for k in 0..20 {
            let a = k as f64 * 0.7;
            let truth = Pose2::new(3.0 * a.cos(), 2.5 * (1.3 * a).sin(), 0.9 * a);
            // The sixth scan laid 20° off: a wrong match the scans after it see through.
            let laid = if k == 5 {
                Pose2::new(truth.x, truth.y, truth.theta + 0.35)
            } else {
                truth
            };
            map.insert_scan(&world.scan(&truth, 0.005, k + 1), &laid, Some(carving))
                .expect("finite points");
        }
        map
    }
    let plain = room(BruteForce::default());
    let boxed = room::<Box<dyn AnyIndex>>(Box::new(BruteForce::default()));
    assert!(plain.stale_len() > 0, "the wrong wall was carved");
    assert_eq!(boxed.renumberings(), 0, "carved in place");
    assert_eq!(
        boxed.index().points(),
        plain.index().points(),
        "the same ids"
    );
    assert_eq!(boxed.live_points(), plain.live_points());

    let mut index: Box<dyn AnyIndex> = Box::new(BruteForce::default());
    index.insert(Point2::new(0.0, 0.0)).unwrap();
    index.insert(Point2::new(1.0, 0.0)).unwrap();
    let before = index.revision();
    assert!(before.is_some(), "the box passes the revision on");
    assert_eq!(index.remove(1), Some(true));
    assert_ne!(index.revision(), before, "a removal is a new revision");
    assert_eq!(index.nearest(&Point2::new(1.0, 0.1)).map(|n| n.id), Some(0));
}
