//! The input perturbations, seeded and deterministic.

use super::*;

/// A standard normal sample.
pub(super) fn standard_normal(rng: &mut impl Rng) -> f64 {
    rng.sample(rand_distr::StandardNormal)
}

/// `scans/2` models a laser (or a matcher) running at half the rate: records 0, 2, 4… kept.
#[must_use]
pub fn every_other_record(records: &[Record]) -> Vec<Record> {
    records.iter().step_by(2).cloned().collect()
}

/// `beams/2` models a laser of half the angular resolution: beams 0, 2, 4… kept, the bearing
/// step doubled, so every kept beam keeps its bearing.
pub fn every_other_beam(scan: &Scan) -> Result<Scan, ScanError> {
    let ranges = scan.ranges().iter().step_by(2).copied().collect();
    let geometry = BeamGeometry {
        angle_increment: scan.geometry.angle_increment * 2.0,
        ..scan.geometry
    };
    Scan::new(scan.timestamp, geometry, ranges)
}

/// `range-noise` models a noisier range finder: Gaussian noise of σ `sigma` (m) on every
/// valid reading; no-returns and invalid readings stay as they are.
pub fn noisy_ranges(scan: &Scan, sigma: f64, rng: &mut impl Rng) -> Result<Scan, ScanError> {
    let ranges = scan
        .ranges()
        .iter()
        .zip(scan.status())
        .map(|(&r, &s)| {
            if s == BeamStatus::Valid {
                r + sigma * standard_normal(rng)
            } else {
                r
            }
        })
        .collect();
    Scan::new(scan.timestamp, scan.geometry, ranges)
}

/// `max-range-10` models a shorter-sighted laser: readings at or beyond `max_range` (m) become
/// no-returns (the geometry's maximum range lowered to it, if higher).
pub fn capped_range(scan: &Scan, max_range: f64) -> Result<Scan, ScanError> {
    let geometry = BeamGeometry {
        max_range: scan.geometry.max_range.min(max_range),
        ..scan.geometry
    };
    Scan::new(scan.timestamp, geometry, scan.ranges().to_vec())
}

/// The odometry poses with every increment `poses[i-1].between(&poses[i])` (robot frame)
/// passed through `perturb` and recomposed from the first pose, so that a perturbation of one
/// increment carries into every later pose, as drift does. A reading that repeats the one
/// before (wheels that did not turn; a stall) repeats in the copy too, exactly: recomposed,
/// its zero increment would leave rounding noise that no longer reads as a repeat.
pub fn perturb_increments(poses: &[Pose2], mut perturb: impl FnMut(Pose2) -> Pose2) -> Vec<Pose2> {
    let mut out = Vec::with_capacity(poses.len());
    let mut current = None::<Pose2>;
    for (i, pose) in poses.iter().enumerate() {
        let next = match (current, i.checked_sub(1)) {
            (Some(c), Some(prev)) => {
                // Drawn for every increment, so that a repeat leaves the later draws alone.
                let step = perturb(poses[prev].between(pose));
                if poses[prev] == *pose {
                    c
                } else {
                    c.compose(&step)
                }
            }
            _ => *pose,
        };
        out.push(next);
        current = Some(next);
    }
    out
}

/// The records with their odometry re-derived by [`perturb_increments`].
pub fn with_odometry_increments(
    records: &[Record],
    perturb: impl FnMut(Pose2) -> Pose2,
) -> Vec<Record> {
    let poses: Vec<Pose2> = records.iter().map(|r| r.odometry).collect();
    records
        .iter()
        .zip(perturb_increments(&poses, perturb))
        .map(|(r, odometry)| {
            let mut out = r.clone();
            out.odometry = odometry;
            out
        })
        .collect()
}

/// `odom-noise` models random wheel-odometry error: x and y of the increment get Gaussian
/// noise of σ 5 cm per metre travelled, the heading σ 2° per metre travelled plus 0.05 rad
/// per radian turned.
pub fn noisy_increment(d: Pose2, rng: &mut impl Rng) -> Pose2 {
    let dist = d.x.hypot(d.y);
    let sigma_xy = ODOM_NOISE_XY_PER_M * dist;
    let sigma_theta = ODOM_NOISE_THETA_PER_M * dist + ODOM_NOISE_THETA_PER_RAD * d.theta.abs();
    // Always three draws, so that one increment's noise never shifts the next one's.
    let (nx, ny, nt) = (
        standard_normal(rng),
        standard_normal(rng),
        standard_normal(rng),
    );
    Pose2::new(
        d.x + sigma_xy * nx,
        d.y + sigma_xy * ny,
        d.theta + sigma_theta * nt,
    )
}

/// `odom-bias` models a slipping or mis-calibrated wheel: the increment's translation scaled
/// by 1.05 and 1° per metre travelled added to its heading (a drift to the left).
#[must_use]
pub fn biased_increment(d: Pose2) -> Pose2 {
    let dist = d.x.hypot(d.y);
    Pose2::new(
        ODOM_BIAS_SCALE * d.x,
        ODOM_BIAS_SCALE * d.y,
        d.theta + ODOM_BIAS_THETA_PER_M * dist,
    )
}
