//! Each pair's terms of the point-to-line system, kept per scan point while the pair forms
//! again within one match.

use crate::PlIcpParams;
use crate::solve::{PairTerms, SymmetricSums};
use nalgebra::{Matrix2, Vector2};
use qicp_core::{Pair, Point2, Reference, SpatialIndex};

/// The weight (2×2 information) of a pair at reference point `id`: `n nᵀ/σ²` along the
/// normal, `tangent_weight` of it along the line; isotropic without a normal. It is
/// symmetric bit for bit (`n₀n₁ = n₁n₀`).
pub(crate) fn weight<I: SpatialIndex>(
    params: &PlIcpParams,
    reference: &Reference<I>,
    id: u32,
) -> Matrix2<f64> {
    let at = &reference.info()[id as usize];
    let n = at.normal;
    if n == Vector2::zeros() {
        return Matrix2::identity() / (params.sigma * params.sigma);
    }
    // The reference point's own noise across its line, twice (the scan point's is alike).
    let info = 1.0 / (params.sigma * params.sigma + 2.0 * n.dot(&(at.covariance * n)));
    let t = Vector2::new(-n.y, n.x);
    (n * n.transpose() + t * t.transpose() * params.tangent_weight) * info
}

/// A scan point's last pair in one call and its terms of the system.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct CachedTerms {
    /// The call in the high 32 bits, the reference point in the low ones; 0: none.
    key: u64,
    /// [`SymmetricSums::terms`] of the pair; the weight `[w00, w01, w11]` leads them.
    terms: PairTerms,
}

/// The terms of `pair` in call `call`, from `cache` (by scan point) when the scan point formed
/// the same pair before in this call.
#[inline(always)]
pub(crate) fn cached_terms<'c, I: SpatialIndex>(
    cache: &'c mut [CachedTerms],
    call: u32,
    params: &PlIcpParams,
    reference: &Reference<I>,
    local: &[Point2<f64>],
    pair: &Pair,
) -> &'c PairTerms {
    let key = (u64::from(call) << 32) | u64::from(pair.reference);
    let slot = &mut cache[pair.scan as usize];
    if slot.key != key {
        *slot = fresh_terms(key, params, reference, local, pair);
    }
    &slot.terms
}

/// The entry of `pair` under `key` for [`cached_terms`], out of its hot loop.
#[inline(never)]
fn fresh_terms<I: SpatialIndex>(
    key: u64,
    params: &PlIcpParams,
    reference: &Reference<I>,
    local: &[Point2<f64>],
    pair: &Pair,
) -> CachedTerms {
    let w = weight(params, reference, pair.reference);
    let q = &reference.index().points()[pair.reference as usize];
    let w = [w[(0, 0)], w[(0, 1)], w[(1, 1)]];
    CachedTerms {
        key,
        terms: SymmetricSums::terms(&local[pair.scan as usize], q, &w),
    }
}
