//! Per-point surface information of a scan: normals face the sensor, and linearity tells a
//! straight wall (1) from a tree trunk or a lone point (0).

use qicp_core::testdata::SyntheticWorld;
use qicp_core::{LaserNoise, Pose2, scan_point_info};

fn info_of(world: &SyntheticWorld, pose: Pose2) -> (qicp_core::Scan, Vec<qicp_core::PointInfo>) {
    let scan = world.scan(&pose, 0.01, 7);
    let info = scan_point_info(&scan, &LaserNoise::default());
    (scan, info)
}

#[test]
fn points_on_a_wall_are_linear_and_face_the_sensor() {
    let (scan, info) = info_of(&SyntheticWorld::featureless_corridor(), Pose2::IDENTITY);
    assert!(scan.valid_count() > 150);
    let linear = info.iter().filter(|i| i.linearity > 0.99).count();
    // Noise alone pushes a few windows past 2σ; nearly all stay straight.
    assert!(
        linear as f64 > 0.85 * info.len() as f64,
        "{linear} of {}",
        info.len()
    );
    for (p, i) in scan.points().iter().zip(&info) {
        assert!(
            i.normal.dot(&p.coords) <= 0.0,
            "normal must face the sensor"
        );
        assert!((0.0..=1.0).contains(&i.linearity));
    }
}

#[test]
fn points_on_distant_trunks_are_not_linear() {
    // Trunks of radius 0.3 m at 8-14 m, as in the park: three to four beams each, on a surface
    // whose curvature shows well above the 1 cm range noise.
    let world = SyntheticWorld {
        walls: vec![],
        posts: vec![
            (8.0, 3.0, 0.3),
            (10.0, -4.0, 0.3),
            (12.0, 6.0, 0.3),
            (14.0, 0.0, 0.3),
        ],
    };
    let (scan, info) = info_of(&world, Pose2::IDENTITY);
    assert!(scan.valid_count() >= 10, "{}", scan.valid_count());
    let mean = info.iter().map(|i| i.linearity).sum::<f64>() / info.len() as f64;
    assert!(mean < 0.2, "mean linearity {mean} on trunks");
}

#[test]
fn lone_points_and_pairs_prove_no_line() {
    // One wall segment hit by two beams only, far away: nothing to tell a line from.
    let world = SyntheticWorld {
        walls: vec![[20.0, -0.3, 20.0, 0.3]],
        posts: vec![],
    };
    let (scan, info) = info_of(&world, Pose2::IDENTITY);
    assert!(scan.valid_count() <= 2, "{}", scan.valid_count());
    assert!(info.iter().all(|i| i.linearity == 0.0));
}

#[test]
fn normal_sigma_predicts_how_far_noise_turns_a_fitted_normal() {
    // A wall 1.5 m ahead, lasers of 91 to 361 beams over 180° with 1 cm range noise: the
    // normal fitted straight ahead turns at random by about the deviation the fit predicts,
    // four times more where the samples lie four times closer together.
    let wall = SyntheticWorld {
        walls: vec![[1.5, -20.0, 1.5, 20.0]],
        posts: vec![],
    };
    let noise = LaserNoise::default();
    let mut predicted = Vec::new();
    for beams in [91, 181, 361] {
        let (mut sum_sq, mut sigma, trials) = (0.0, 0.0, 400u32);
        for seed in 0..u64::from(trials) {
            let scan = wall.scan_with_beams(&Pose2::IDENTITY, beams, noise.sigma_range, seed);
            let info = scan_point_info(&scan, &noise);
            let ahead = (0..info.len())
                .min_by(|&a, &b| {
                    let (a, b) = (scan.point_angle(a).abs(), scan.point_angle(b).abs());
                    a.total_cmp(&b)
                })
                .expect("the wall is seen");
            let i = info[ahead];
            // The true normal is −x.
            sum_sq += i.normal.y.atan2(-i.normal.x).powi(2);
            sigma += i.normal_sigma;
        }
        let (seen, sigma) = (
            (sum_sq / f64::from(trials)).sqrt(),
            sigma / f64::from(trials),
        );
        assert!(
            (0.7..1.5).contains(&(sigma / seen)),
            "{beams} beams: predicted {sigma:.4} rad, seen {seen:.4} rad"
        );
        predicted.push(sigma);
    }
    assert!(
        predicted[2] > 3.0 * predicted[0],
        "predicted deviations {predicted:?}"
    );
}
