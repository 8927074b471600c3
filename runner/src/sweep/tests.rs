//! The sweep's variants, perturbations and parallel runs, on small seeded cases.

use super::*;

fn scan(ranges: Vec<f64>) -> Scan {
    let geometry = BeamGeometry {
        angle_min: -1.0,
        angle_increment: 0.1,
        max_range: 20.0,
        min_range: 0.1,
    };
    Scan::new(3.0, geometry, ranges).expect("valid scan")
}

fn records(odometry: &[Pose2]) -> Vec<Record> {
    odometry
        .iter()
        .enumerate()
        .map(|(i, &odometry)| Record {
            scan: Scan::new(i as f64, BeamGeometry::centered(5, 1.0, 20.0), vec![1.0; 5])
                .expect("valid scan"),
            odometry,
            truth: None,
            laser_offset: Pose2::IDENTITY,
        })
        .collect()
}

/// A straight drive along x from the origin in `steps` equal steps.
fn straight(length: f64, steps: usize) -> Vec<Pose2> {
    (0..=steps)
        .map(|i| Pose2::new(length * i as f64 / steps as f64, 0.0, 0.0))
        .collect()
}

/// A seeded random drive: wandering odometry, ranges with no-returns and invalid readings.
fn random_records(n: usize, seed: u64) -> Vec<Record> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut odometry = Pose2::new(1.0, -2.0, 0.3);
    (0..n)
        .map(|i| {
            let step = Pose2::new(
                rng.random_range(0.0..0.3),
                rng.random_range(-0.05..0.05),
                rng.random_range(-0.2..0.2),
            );
            odometry = odometry.compose(&step);
            let ranges = (0..37)
                .map(|_| match rng.random_range(0..10) {
                    0 => -1.0,
                    1 => 30.0,
                    _ => rng.random_range(0.2..18.0),
                })
                .collect();
            Record {
                scan: Scan::new(
                    0.1 * i as f64,
                    BeamGeometry::centered(37, 3.0, 20.0),
                    ranges,
                )
                .expect("valid scan"),
                odometry,
                truth: None,
                laser_offset: Pose2::IDENTITY,
            }
        })
        .collect()
}

#[test]
fn a_streamed_input_variant_gives_the_records_of_the_whole_log_form() {
    for seed in 0..3 {
        let records = random_records(41, seed);
        for variant in InputVariant::ALL {
            let whole = variant.apply(&records).expect("applies");
            let streamed: Vec<Record> = variant
                .stream(records.iter().cloned().map(Ok))
                .collect::<Result<_>>()
                .expect("streams");
            assert_eq!(streamed, whole, "{} (seed {seed})", variant.name());
            assert_ne!(streamed, records, "{} changed nothing", variant.name());
        }
    }
}

#[test]
fn a_streamed_input_variant_passes_errors_on_and_keeps_going() {
    let records = random_records(6, 1);
    let input = records.iter().enumerate().map(|(i, r)| {
        if i == 2 {
            Err(anyhow::anyhow!("bad line"))
        } else {
            Ok(r.clone())
        }
    });
    let out: Vec<Result<Record>> = InputVariant::EveryOtherRecord.stream(input).collect();
    // Records 0, 1, 3, 4, 5 count; 0, 3 and 5 are kept, and the error is not lost.
    assert_eq!(out.len(), 4);
    assert!(out[1].as_ref().is_err_and(|e| e.to_string() == "bad line"));
    let kept: Vec<f64> = out.iter().flatten().map(Record::timestamp).collect();
    assert_eq!(kept, [0.0, 0.1 * 3.0, 0.1 * 5.0]);
}

#[test]
fn every_other_beam_halves_the_beams_and_keeps_their_bearings() {
    let s = scan((0..11).map(|i| 1.0 + f64::from(i)).collect());
    let half = every_other_beam(&s).expect("valid");
    assert_eq!(half.beams(), 6);
    for (k, i) in (0..11).step_by(2).enumerate() {
        assert!((half.geometry.angle(k) - s.geometry.angle(i)).abs() < 1e-12);
        assert_eq!(half.ranges()[k], s.ranges()[i]);
    }
}

#[test]
fn every_other_record_keeps_the_even_ones() {
    let r = records(&straight(1.0, 4));
    let kept: Vec<f64> = every_other_record(&r)
        .iter()
        .map(Record::timestamp)
        .collect();
    assert_eq!(kept, [0.0, 2.0, 4.0]);
}

#[test]
fn odometry_bias_on_a_straight_metre() {
    // One increment of 1 m: exactly 1.05 m and 1°.
    let one = biased_increment(Pose2::new(1.0, 0.0, 0.0));
    assert!((one.x - 1.05).abs() < 1e-12 && one.y.abs() < 1e-12);
    assert!((one.theta.to_degrees() - 1.0).abs() < 1e-12);
    // A hundred 1 cm steps: 1.05 m travelled on a gentle arc, 1° turned in all.
    let poses = perturb_increments(&straight(1.0, 100), biased_increment);
    let end = poses.last().copied().unwrap_or_default();
    assert!((end.x.hypot(end.y) - 1.05).abs() < 1e-4, "{end:?}");
    assert!((end.theta.to_degrees() - 1.0).abs() < 1e-9, "{end:?}");
    assert_eq!(poses.first().copied(), Some(Pose2::IDENTITY));
}

#[test]
fn perturbed_odometry_starts_at_the_first_pose_and_keeps_it_unperturbed() {
    let start = Pose2::new(3.0, -2.0, 0.5);
    let path: Vec<Pose2> = straight(2.0, 10).iter().map(|p| start.compose(p)).collect();
    let same = perturb_increments(&path, |d| d);
    for (a, b) in path.iter().zip(&same) {
        assert!(a.distance(b) < 1e-9 && (a.theta - b.theta).abs() < 1e-9);
    }
    let biased = perturb_increments(&path, biased_increment);
    assert_eq!(biased.first(), path.first());
    let end = biased.last().copied().unwrap_or_default();
    assert!((start.distance(&end) - 2.1).abs() < 1e-3, "{end:?}");
}

#[test]
fn a_stall_repeats_its_reading_exactly_in_perturbed_odometry() {
    // Readings as a CARMEN log holds them (MIT CSAIL's first stall): far from the origin,
    // turned, and repeated for four records before a catch-up.
    let start = Pose2::new(574.078178, -2.712098, 2.884097);
    let mut path: Vec<Pose2> = straight(1.0, 5).iter().map(|p| start.compose(p)).collect();
    let stall = path.last().copied().unwrap_or_default();
    path.extend([stall; 4]);
    path.push(stall.compose(&Pose2::new(0.8, 0.2, 0.87)));
    let mut rng = ChaCha8Rng::seed_from_u64(SEED);
    for perturbed in [
        perturb_increments(&path, biased_increment),
        perturb_increments(&path, |d| noisy_increment(d, &mut rng)),
    ] {
        assert!(
            perturbed[6..10].iter().all(|p| *p == perturbed[5]),
            "{perturbed:?}"
        );
        assert_ne!(perturbed[10], perturbed[5]);
    }
}

#[test]
fn odometry_noise_is_deterministic_for_a_seed_and_drifts() {
    let r = records(&straight(5.0, 50));
    let a = InputVariant::OdometryNoise.apply(&r).expect("applies");
    let b = InputVariant::OdometryNoise.apply(&r).expect("applies");
    assert_eq!(a, b);
    let mut rng = ChaCha8Rng::seed_from_u64(SEED + 1);
    let poses: Vec<Pose2> = r.iter().map(|r| r.odometry).collect();
    let c = perturb_increments(&poses, |d| noisy_increment(d, &mut rng));
    assert_ne!(a.last().map(|r| r.odometry), c.last().copied());
    let drift = a
        .last()
        .zip(r.last())
        .map(|(a, r)| a.odometry.distance(&r.odometry))
        .unwrap_or_default();
    assert!(drift > 1e-4 && drift < 1.5, "drift {drift}");
    // A robot standing still gets no noise.
    let still = perturb_increments(&[Pose2::IDENTITY; 5], |d| noisy_increment(d, &mut rng));
    assert!(still.iter().all(|p| *p == Pose2::IDENTITY));
}

#[test]
fn range_noise_leaves_invalid_readings_alone() {
    let s = scan(vec![1.0, f64::NAN, 25.0, 0.05, 2.0, -1.0, 3.0]);
    let mut rng = ChaCha8Rng::seed_from_u64(SEED);
    let noisy = noisy_ranges(&s, 0.01, &mut rng).expect("valid");
    for (i, (&before, &after)) in s.ranges().iter().zip(noisy.ranges()).enumerate() {
        if s.status()[i] == BeamStatus::Valid {
            assert_ne!(before, after);
            assert!((before - after).abs() < 0.06);
        } else {
            assert!(before.to_bits() == after.to_bits(), "beam {i} changed");
        }
    }
}

#[test]
fn capped_range_turns_far_returns_into_no_returns() {
    let s = scan(vec![1.0, 9.9, 10.0, 15.0]);
    let capped = capped_range(&s, 10.0).expect("valid");
    assert_eq!(capped.valid_count(), 2);
    assert_eq!(capped.status()[3], BeamStatus::MaxRange);
    assert_eq!(capped.ranges(), s.ranges());
    // A laser that sees less than 10 m keeps its own range.
    let near = capped_range(&capped_range(&s, 5.0).expect("valid"), 10.0).expect("valid");
    assert!((near.geometry.max_range - 5.0).abs() < 1e-12);
}

#[test]
fn variants_follow_the_steering_parameters() {
    let config = MatcherConfig::defaults(qicp_matchers::MatcherKind::QWsm);
    let all = all_variants(&config);
    let parameters = config.steering_parameters();
    assert_eq!(all.len(), InputVariant::ALL.len() + 2 * parameters.len());
    assert!(all.iter().any(|v| v.name == "icp.max_dist_start*0.7"));
    assert!(all.iter().any(|v| v.name == "icp.max_dist_start*1.4"));
    let names = [
        "odom-bias".to_string(),
        "scans/2".to_string(),
        "default".to_string(),
    ];
    let picked = select_variants(all.clone(), &names).expect("known");
    let picked: Vec<&str> = picked.iter().map(|v| v.name.as_str()).collect();
    assert_eq!(picked, ["scans/2", "odom-bias"]);
    let err = select_variants(all, &["nope".to_string()]).expect_err("unknown");
    let msg = err.to_string();
    assert!(msg.contains("nope") && msg.contains("beams/2"), "{msg}");
}

#[test]
fn the_old_name_of_the_laser_noise_variant_still_selects_it() {
    let all = all_variants(&MatcherConfig::defaults(qicp_matchers::MatcherKind::QWsm));
    let names = ["wsm.sigma_range*0.7".to_string()];
    let picked = select_variants(all.clone(), &names).expect("the old name is known");
    let picked: Vec<&str> = picked.iter().map(|v| v.name.as_str()).collect();
    assert_eq!(picked, ["laser.sigma_range*0.7"]);
    assert_eq!(current_name("wsm.sigma_slide*0.7"), "wsm.sigma_slide*0.7");
    assert_eq!(
        current_name("wsm.sigma_range"),
        "wsm.sigma_range",
        "no factor, no rename"
    );
    let err = select_variants(all, &["wsm.sigma_range*0.5".to_string()]).expect_err("no 0.5");
    assert!(
        err.to_string()
            .contains("unknown variant wsm.sigma_range*0.5;"),
        "named as given: {err}"
    );
}

#[test]
fn parallel_results_are_in_item_order_and_panics_are_errors() {
    let items: Vec<u32> = (0..20).collect();
    for jobs in [1, 3, 64] {
        let mut seen = 0;
        let out = run_parallel(
            &items,
            jobs,
            |&i| {
                if i == 7 {
                    panic!("seven");
                }
                Ok(i * 2)
            },
            |_, _, _| seen += 1,
        );
        assert_eq!(seen, 20);
        for (i, r) in out.iter().enumerate() {
            match r {
                Ok(v) => assert_eq!(*v as usize, i * 2),
                Err(e) => assert!(i == 7 && e.contains("seven"), "{e}"),
            }
        }
    }
}

fn variant_with(name: &str, trans_mean: Option<f64>) -> VariantReport {
    VariantReport {
        name: name.to_string(),
        figures: trans_mean.map(|trans_mean| RunFigures {
            trans_mean,
            trans_max: trans_mean,
            rot_mean_deg: 0.0,
            ms_per_scan_median: 1.0,
            map_points: 0,
            scans: 10,
            relations: 10,
            relations_missing: 0,
            relations_over_0_5_m: 0,
            relation_errors: Vec::new(),
        }),
        ratio: None,
        default_trans_mean: None,
        error: trans_mean.is_none().then(|| "could not run".to_string()),
    }
}

#[test]
fn robustness_figures_count_the_variants_over_the_bound_and_their_geometric_mean() {
    // Seeded random sweeps, against a count and a product computed one variant at a time.
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    for _ in 0..200 {
        let default = rng.random_range(0.001..0.2);
        let variants: Vec<VariantReport> = (0..rng.random_range(0..40))
            .map(|i| {
                let ran = rng.random_range(0.0..1.0) < 0.9;
                variant_with(&format!("v{i}"), ran.then(|| rng.random_range(0.001..1.0)))
            })
            .collect();
        let (over, geomean) = robustness_figures(default, &variants);
        let bound = f64::max(2.0 * default, 0.05);
        let ran: Vec<f64> = variants
            .iter()
            .filter_map(|v| v.figures.as_ref().map(|f| f.trans_mean))
            .collect();
        assert_eq!(over, ran.iter().filter(|&&e| e > bound).count());
        match geomean {
            None => assert!(ran.is_empty()),
            Some(g) => {
                let product: f64 = ran.iter().product();
                let expected = product.powf(1.0 / ran.len() as f64);
                assert!((g - expected).abs() <= 1e-9 * expected, "{g} vs {expected}");
            }
        }
    }
    // The bound's floor: at a 1 cm default a variant at 4 cm is within it, one at 6 cm over.
    let (over, _) = robustness_figures(
        0.01,
        &[variant_with("a", Some(0.04)), variant_with("b", Some(0.06))],
    );
    assert_eq!(over, 1);
    // A variant whose error is not a number is over any bound.
    let (over, geomean) = robustness_figures(0.01, &[variant_with("nan", Some(f64::NAN))]);
    assert_eq!((over, geomean), (1, None));
}

#[test]
fn relations_along_a_trajectory_hold_its_own_motion_per_metre_or_30_degrees() {
    // Three metres in 10 cm steps, then a quarter turn in place in 5° steps.
    let mut poses = straight(3.0, 30);
    for k in 1..=18 {
        poses.push(Pose2::new(3.0, 0.0, (5.0 * k as f64).to_radians()));
    }
    let trajectory: Vec<Stamped> = poses
        .iter()
        .enumerate()
        .map(|(i, p)| (i as f64, *p))
        .collect();
    let relations = relations_along(&trajectory);
    // Segments end on the first pose a metre on (three along x), then every 30° (three).
    assert_eq!(relations.len(), 6, "{relations:?}");
    assert!((relations[0].delta.x - 1.0).abs() < 1e-9 && relations[0].t1 == 0.0);
    assert!((relations[5].delta.theta - 30f64.to_radians()).abs() < 1e-9);
    // The trajectory agrees with itself, and so does a copy moved and turned as a whole.
    let mut figures = scored(&trajectory, &relations);
    assert_eq!((figures.trans_mean, figures.relations), (0.0, 6));
    let offset = Pose2::new(-4.0, 2.5, 1.1);
    let moved: Vec<Stamped> = trajectory.iter().map(|(t, p)| (*t, offset * *p)).collect();
    figures.score(&moved, &relations).expect("scores");
    assert!(figures.trans_max < 1e-9, "{figures:?}");
    // A run that slipped 20 cm along x in its second metre disagrees there, and only there.
    let slipped: Vec<Stamped> = trajectory
        .iter()
        .map(|(t, p)| {
            let slip = (p.x - 1.0).clamp(0.0, 1.0) * 0.2;
            (*t, Pose2::new(p.x + slip, p.y, p.theta))
        })
        .collect();
    figures.score(&slipped, &relations).expect("scores");
    assert!((figures.trans_max - 0.2).abs() < 1e-9, "{figures:?}");
    assert!((figures.trans_mean - 0.2 / 6.0).abs() < 1e-9, "{figures:?}");
    // Too short a drive has no segment.
    assert!(relations_along(&trajectory[..5]).is_empty());
    assert!(relations_along(&[]).is_empty());
}

/// A 10 m square driven `laps` times at 0.1 m a second, a pose a second.
fn square_laps(laps: usize) -> Vec<Stamped> {
    let corners = [(0.0, 0.0), (10.0, 0.0), (10.0, 10.0), (0.0, 10.0)];
    let mut out = Vec::new();
    for _ in 0..laps {
        for (side, (x, y)) in corners.into_iter().enumerate() {
            let heading = side as f64 * std::f64::consts::FRAC_PI_2;
            for i in 0..100 {
                let d = 0.1 * f64::from(i);
                let t = out.len() as f64;
                let pose = Pose2::new(x + d * heading.cos(), y + d * heading.sin(), heading);
                out.push((t, pose));
            }
        }
    }
    out
}

#[test]
fn a_heading_lost_once_is_caught_by_the_revisits_not_by_the_segments() {
    // Three laps of a square, 400 s each: every pose after the first lap comes back within a
    // metre of one 400 s older.
    let truth = square_laps(3);
    let relations = relations_along(&truth);
    let revisits: Vec<&Relation> = relations.iter().filter(|r| r.t2 - r.t1 >= 60.0).collect();
    assert!(revisits.len() >= 70, "{} revisits", revisits.len());
    // One a pose, from the nearest earlier pose: after the first lap, the same place of the
    // lap before (the first lap's end comes back near its start).
    assert!(
        revisits
            .iter()
            .filter(|r| r.t2 >= 400.0)
            .all(|r| (r.t2 - r.t1 - 400.0).abs() < 1e-9 && r.delta.translation().norm() < 1e-9)
    );
    assert_eq!(scored(&truth, &relations).trans_max, 0.0);
    // A run that turns 40° at once half-way and follows the truth's motion after: one bad
    // match, its map turned with it.
    let at = truth.len() / 2;
    let pivot = truth[at].1;
    let turn = pivot * Pose2::new(0.0, 0.0, 40f64.to_radians()) * pivot.inverse();
    let lost: Vec<Stamped> = truth
        .iter()
        .enumerate()
        .map(|(i, (t, p))| (*t, if i < at { *p } else { turn * *p }))
        .collect();
    // The chain alone sees it on one segment of about 120: a centimetre on the mean.
    let chain: Vec<Relation> = relations
        .iter()
        .filter(|r| r.t2 - r.t1 < 60.0)
        .cloned()
        .collect();
    assert!(scored(&lost, &chain).trans_mean < 0.02);
    // The revisits across the turn disagree by metres.
    assert!(scored(&lost, &relations).trans_mean > 1.0);
}

/// Figures of `poses` (at times 0, 1, 2, …) scored with `relations`.
fn scored(poses: &[(f64, Pose2)], relations: &[Relation]) -> RunFigures {
    let mut figures = RunFigures {
        trans_mean: f64::NAN,
        trans_max: f64::NAN,
        rot_mean_deg: f64::NAN,
        ms_per_scan_median: 0.0,
        map_points: 0,
        scans: poses.len(),
        relations: 0,
        relations_missing: 0,
        relations_over_0_5_m: 0,
        relation_errors: Vec::new(),
    };
    figures.score(poses, relations).expect("scores");
    figures
}

#[test]
fn a_variant_scored_on_fewer_relations_is_compared_with_the_default_on_the_same_ones() {
    // Five records a metre apart along x, and relations between them.
    let at = |t: f64, x: f64| (t, Pose2::new(x, 0.0, 0.0));
    let relation = |t1: f64, t2: f64| Relation {
        t1,
        t2,
        delta: Pose2::new(t2 - t1, 0.0, 0.0),
    };
    let relations = [
        relation(0.0, 1.0),
        relation(1.0, 2.0),
        relation(0.0, 2.0),
        relation(2.0, 4.0),
    ];
    // The default errs by 0.3 m at record 1 and by 0.02 m at record 4: 0.155 m over all four
    // relations, 0.01 m over the two between even records.
    let default = scored(
        &[
            at(0.0, 0.0),
            at(1.0, 1.3),
            at(2.0, 2.0),
            at(3.0, 3.0),
            at(4.0, 4.02),
        ],
        &relations,
    );
    assert!((default.trans_mean - 0.155).abs() < 1e-12, "{default:?}");
    // A run of the even records (as `scans/2`) errs by 0.2 m at record 4: 0.1 m over the two
    // relations it can score.
    let halved = scored(&[at(0.0, 0.0), at(2.0, 2.0), at(4.0, 4.2)], &relations);
    assert_eq!((halved.relations, halved.relations_missing), (2, 2));
    assert!((halved.trans_mean - 0.1).abs() < 1e-12, "{halved:?}");
    let report = variant_report("scans/2", Ok(halved), &default);
    // Ten times the default on the same relations, not 0.65 times its mean over all four.
    let same = report
        .default_trans_mean
        .expect("a default on the same relations");
    assert!((same - 0.01).abs() < 1e-12, "{report:?}");
    assert!(
        (report.ratio.expect("a ratio") - 10.0).abs() < 1e-9,
        "{report:?}"
    );
    // Over its bound max(2 × 0.01, 0.05) m, though within the whole default's 0.31 m.
    assert_eq!(robustness_figures(default.trans_mean, &[report]).0, 1);
    // A variant that scores every relation keeps the plain ratio.
    let full = scored(
        &[
            at(0.0, 0.0),
            at(1.0, 1.0),
            at(2.0, 2.0),
            at(3.0, 3.0),
            at(4.0, 4.0),
        ],
        &relations,
    );
    let report = variant_report("full", Ok(full), &default);
    assert_eq!(report.default_trans_mean, None);
    assert_eq!(report.ratio, Some(0.0));
}
