//! The scan's own surface normals, without the rest of what the reference keeps per point.

use nalgebra::Vector2;
use qicp_core::{Scan, surface_connections, surface_normal};

/// The normals of [`qicp_core::scan_point_info`], bit for bit (the same functions compute
/// them), into `out`, without the covariance, spacing and linearity the matcher does not
/// read. `connected` is scratch.
pub(crate) fn scan_normals(scan: &Scan, connected: &mut Vec<bool>, out: &mut Vec<Vector2<f64>>) {
    surface_connections(scan, connected);
    let pts = scan.points();
    out.clear();
    out.extend((0..pts.len()).map(|k| surface_normal(pts, connected, k)));
}

#[cfg(test)]
mod tests {
    use super::*;
    use qicp_core::testdata::{SplitMix, SyntheticWorld};
    use qicp_core::{BeamGeometry, LaserNoise, Pose2, scan_point_info};

    fn assert_same(scan: &Scan, what: &str) {
        let (mut connected, mut normals) = (Vec::new(), Vec::new());
        scan_normals(scan, &mut connected, &mut normals);
        let plain: Vec<_> = scan_point_info(scan, &LaserNoise::default())
            .iter()
            .map(|i| i.normal)
            .collect();
        assert_eq!(normals.len(), plain.len(), "{what}");
        for (k, (a, b)) in normals.iter().zip(&plain).enumerate() {
            assert!(
                a.x.to_bits() == b.x.to_bits() && a.y.to_bits() == b.y.to_bits(),
                "{what}, point {k}: {a:?} vs {b:?}"
            );
        }
    }

    #[test]
    fn the_normals_are_scan_point_info_s_bit_for_bit() {
        let mut rng = SplitMix::new(5);
        // Random ranges: jumps, no-returns, too-close readings, runs of a wall.
        for round in 0..300 {
            let beams = 2 + (rng.unit() * 400.0) as usize;
            let fov = rng.range(0.5, 6.0);
            let mut geometry = BeamGeometry::centered(beams, fov, 30.0);
            geometry.min_range = 0.05;
            if round % 3 == 0 {
                geometry.angle_increment = -geometry.angle_increment;
                geometry.angle_min = -geometry.angle_min;
            }
            let mut r = rng.range(0.5, 10.0);
            let ranges = (0..beams)
                .map(|_| match (rng.unit() * 10.0) as u32 {
                    0 => 30.0,
                    1 => 0.01,
                    2 => {
                        r = rng.range(0.1, 29.0);
                        r
                    }
                    _ => {
                        r = (r + rng.range(-0.05, 0.05)).clamp(0.1, 29.0);
                        r
                    }
                })
                .collect();
            let scan = Scan::new(0.0, geometry, ranges).expect("a valid scan");
            assert_same(&scan, &format!("random scan {round}"));
        }
        // Scans of synthetic worlds, axis-aligned walls included.
        for (w, world) in [
            SyntheticWorld::room(),
            SyntheticWorld::corridor(),
            SyntheticWorld::posts(),
        ]
        .iter()
        .enumerate()
        {
            for seed in 0..20 {
                let pose = Pose2::new(
                    rng.range(-0.5, 0.5),
                    rng.range(-0.5, 0.5),
                    rng.range(-3.0, 3.0),
                );
                let sigma = if seed % 2 == 0 { 0.0 } else { 0.01 };
                assert_same(
                    &world.scan(&pose, sigma, seed),
                    &format!("world {w}, {seed}"),
                );
            }
        }
    }
}
