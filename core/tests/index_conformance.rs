//! Every spatial index answers every query exactly as the brute-force oracle does: the
//! conformance suite of `qicp_core::conformance` (feature `testkit`), which an index from
//! another crate runs the same way.

qicp_core::index_conformance! {
    quadtree: qicp_core::QuadTree,
    quadtree_bucket_4: qicp_core::QuadTreeN<4>,
    kdtree: qicp_core::KdTree,
    brute: qicp_core::BruteForce,
}
