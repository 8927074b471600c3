//! Insertions and removals interleaved at random: every index answers as the brute-force one
//! after each step, whatever the order (the conformance suite removes in one batch).

use proptest::prelude::*;
use qicp_core::{BruteForce, KdTree, Point2, QuadTree, QuadTreeN, SpatialIndex};

/// One step: insert a point from a small grid (so that duplicates and shared coordinates are
/// common), or remove the id at this fraction of those handed out so far.
#[derive(Debug, Clone)]
enum Op {
    Insert(i32, i32),
    Remove(f64),
}

fn ops() -> impl Strategy<Value = Vec<Op>> {
    let op = prop_oneof![
        3 => (-3i32..4, -3i32..4).prop_map(|(x, y)| Op::Insert(x, y)),
        2 => (0.0..1.0f64).prop_map(Op::Remove),
    ];
    prop::collection::vec(op, 1..300)
}

/// Runs `ops` on `I` and the oracle, comparing after each; `duplicates_by_id`: on a stored
/// point, `I` answers with the lowest id of its duplicates, as the oracle does (the quad tree
/// promises it; kiddo does not).
fn run<I: SpatialIndex + Default>(
    ops: &[Op],
    spacing: f64,
    duplicates_by_id: bool,
) -> Result<(), TestCaseError> {
    let (mut index, mut oracle) = (I::default(), BruteForce::default());
    // Between the grid's points, and on some of them.
    let queries: Vec<Point2<f64>> = (0..12)
        .map(|k| Point2::new(0.37 * k as f64 - 2.0, 1.9 - 0.41 * k as f64) * spacing * 4.0)
        .chain(
            (-3..4)
                .flat_map(|x| (-3..4).map(move |y| Point2::new(f64::from(x), f64::from(y))))
                .map(|p| p * spacing),
        )
        .collect();
    let (mut got, mut want) = (Vec::new(), Vec::new());
    for op in ops {
        match *op {
            Op::Insert(x, y) => {
                let p = Point2::new(f64::from(x) * spacing, f64::from(y) * spacing);
                prop_assert_eq!(index.insert(p).ok(), oracle.insert(p).ok());
            }
            Op::Remove(at) => {
                let id = (at * index.len() as f64) as u32;
                prop_assert_eq!(index.remove(id), oracle.remove(id), "remove {}", id);
            }
        }
        for q in &queries {
            // Equally near points may be answered by either (as in the conformance suite).
            let (a, b) = (index.nearest(q), oracle.nearest(q));
            prop_assert_eq!(a.map(|n| n.dist_sq), b.map(|n| n.dist_sq));
            if duplicates_by_id && b.is_some_and(|n| n.dist_sq == 0.0) {
                // On a stored point only its duplicates tie: the lowest id answers, also
                // after the chain's head was removed.
                prop_assert_eq!(a.map(|n| n.id), b.map(|n| n.id));
            }
            index.within_radius(q, 3.0 * spacing, &mut got);
            oracle.within_radius(q, 3.0 * spacing, &mut want);
            let mut a: Vec<u32> = got.iter().map(|n| n.id).collect();
            let mut b: Vec<u32> = want.iter().map(|n| n.id).collect();
            a.sort_unstable();
            b.sort_unstable();
            prop_assert_eq!(a, b);
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn the_quad_tree_removes_like_the_oracle(ops in ops()) {
        run::<QuadTree>(&ops, 0.1, true)?;
        run::<QuadTreeN<2>>(&ops, 0.1, true)?;
        // Points closer than the smallest cell spill into overflow leaves.
        run::<QuadTreeN<2>>(&ops, 1e-8, true)?;
    }

    #[test]
    fn the_kd_tree_removes_like_the_oracle(ops in ops()) {
        // A grid shares coordinates: kiddo's overflow list and equal split values.
        run::<KdTree>(&ops, 0.1, false)?;
    }
}
