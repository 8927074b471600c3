//! The TOML registry: every kind builds from its defaults, effective configs round-trip, and
//! bad input is refused with a message that names the key.

use qicp_matchers::{ConfigError, MatcherConfig, MatcherKind};

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
    assert_eq!(c.kind, MatcherKind::QWsm);
    assert_eq!(c.icp.max_iterations, 7);
    assert_eq!(c.wsm.unwrap().sigma_range, 0.02);
    assert_eq!(c.relevance.tau_max, 0.5);
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
            "[matcher.icp]\nmax_dist_end = 5.0",
            "matcher.icp.max_dist_end",
        ),
        ("[matcher.icp]\nshrink = 1.5", "matcher.icp.shrink"),
        (
            "[matcher.wsm]\nsigma_range = 0.0",
            "matcher.wsm.sigma_range",
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
            assert!((scaled.parameter(key).unwrap() - v * 1.4).abs() < 1e-12);
            // Nothing else moved.
            for other in keys.iter().filter(|k| *k != key) {
                assert_eq!(scaled.parameter(other), base.parameter(other), "{other}");
            }
        }
    }
    let err = MatcherConfig::defaults(MatcherKind::QWsm)
        .scaled("matcher.icp.nope", 2.0)
        .unwrap_err();
    assert!(err.to_string().contains("matcher.icp.nope"));
}
