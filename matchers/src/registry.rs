//! The open registry: algorithms, spatial indexes and reference policies registered by name,
//! composed by a configuration into a laser-odometry pipeline.
//!
//! A configuration names three axes (`[matcher] algorithm = "wsm"`, `reference = "map"`,
//! `index = "quadtree"`) or one composed name (`kind = "q-wsm"`). Composed names follow one
//! rule for every registered algorithm `A`: `A` matches scan to scan; `<prefix>-A` matches
//! against a map held in the index of that prefix (`q-` quad tree, `kd-` kd-tree, `bf-` brute
//! force). So an algorithm registered by another crate gains its boosted forms (`q-plicp`)
//! without a line of code. Scan to scan over another index is `A@<index>`; against a
//! registered reference policy `P` other than `map` and `scan` it is `A+P` (`A+P@<index>`).
//!
//! ```
//! use qicp_matchers::Registry;
//! let registry = Registry::builtin();
//! let config = registry.config("q-wsm").expect("a built-in preset");
//! assert_eq!((config.algorithm(), config.reference.name(), config.index()), ("wsm", "map", "quadtree"));
//! let pipeline = config.build().expect("its defaults are valid");
//! assert_eq!(pipeline.kind(), "q-wsm");
//! ```

use crate::config::{ConfigError, MatcherConfig};
use crate::correlative::CorrelativeParams;
use crate::icp::IcpParams;
use crate::params::{Param, check_section, parse_section, to_table};
use crate::pipeline::{MotionModel, Odometry, Pipeline, Relevance};
pub use crate::policy::{MAP, ReferenceEntry, SCAN};
use crate::policy::{ReferencePolicy, is_builtin};
use crate::revisit::RevisitParams;
use crate::validation::ValidationParams;
use qicp_core::{
    BruteForce, CorrespondenceMetric, KdTree, LaserNoise, MutualNearest, QuadTree, ScanMatcher,
    SpatialIndex,
};
use serde::Serialize;
use serde::de::DeserializeOwned;
use std::fmt::Debug;
use std::marker::PhantomData;
use std::sync::{Arc, LazyLock};

/// A correspondence metric a registered matcher can be built with (the registry pairs every
/// matcher with the paper's mutual-nearest rule over the chosen index).
pub trait Metric: CorrespondenceMetric + Default + Send + Debug + 'static {}
impl<C: CorrespondenceMetric + Default + Send + Debug + 'static> Metric for C {}

/// A scan-matching algorithm the registry builds by name, for every registered index and
/// reference policy. Implement it for a unit type and call [`Registry::register`].
pub trait Algorithm: 'static {
    /// Registry name, e.g. `"wsm"`; its parameters are the TOML section `[matcher.<NAME>]`.
    const NAME: &'static str;
    /// One line for listings.
    const SUMMARY: &'static str;
    /// Every field of [`Self::Params`], with range and documentation: checked generically.
    const PARAMETERS: &'static [Param];
    /// The parameters; `Default` gives the documented defaults.
    type Params: Serialize + DeserializeOwned + Default + Clone + Debug + PartialEq + Send + Sync;
    /// The matcher, for the correspondence metric `C`.
    type Matcher<C: Metric>: ScanMatcher + Send + Debug + 'static;

    /// This algorithm's defaults for the shared iteration section `[matcher.icp]` (keys the
    /// configuration leaves out take these). Default: [`IcpParams::default`].
    fn icp_defaults() -> IcpParams {
        IcpParams::default()
    }

    /// Builds the matcher.
    fn matcher<C: Metric>(icp: IcpParams, params: &Self::Params) -> Self::Matcher<C>;

    /// Rules that tie parameters together, beyond each one's range (e.g. a window that must
    /// not exceed another).
    fn check(_params: &Self::Params) -> Result<(), ConfigError> {
        Ok(())
    }

    /// True when the matcher weighs pairs by the laser's noise (`[matcher.laser]`, which the
    /// reference holds: [`Reference::noise`](qicp_core::Reference::noise)), so that a
    /// robustness sweep perturbs it. Default false.
    const WEIGHS_BY_LASER_NOISE: bool = false;

    /// The default of `matcher.relevance.map_resolution` for this algorithm and a laser of
    /// `noise` (m): by default its matcher's [`ScanMatcher::map_resolution`], so typed and
    /// registry pipelines agree.
    fn map_resolution(params: &Self::Params, noise: &LaserNoise) -> f64 {
        Self::matcher::<qicp_core::ClosestPoint>(IcpParams::default(), params).map_resolution(noise)
    }

    /// The default of `matcher.relevance.surface_band_sigmas` for this algorithm: by default
    /// its matcher's [`ScanMatcher::surface_band_sigmas`].
    fn surface_band_sigmas(params: &Self::Params) -> f64 {
        Self::matcher::<qicp_core::ClosestPoint>(IcpParams::default(), params).surface_band_sigmas()
    }

    /// The default of `matcher.relevance.min_novelty` for this algorithm: by default its
    /// matcher's [`ScanMatcher::min_novelty`].
    fn min_novelty(params: &Self::Params) -> f64 {
        Self::matcher::<qicp_core::ClosestPoint>(IcpParams::default(), params).min_novelty()
    }
}

/// An index a map can be held in, as the registry knows it.
#[derive(Clone)]
pub struct IndexEntry {
    name: &'static str,
    prefix: &'static str,
    summary: &'static str,
    make: IndexMaker,
}

impl IndexEntry {
    /// Registry name, e.g. `"quadtree"`.
    #[must_use]
    pub fn name(&self) -> &'static str {
        self.name
    }
    /// Prefix of composed names, e.g. `"q"` in `q-wsm`.
    #[must_use]
    pub fn prefix(&self) -> &'static str {
        self.prefix
    }
    /// One line for listings.
    #[must_use]
    pub fn summary(&self) -> &'static str {
        self.summary
    }
}

impl Debug for IndexEntry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name)
    }
}

/// A spatial index behind dynamic dispatch: what an index registered at run time is.
pub trait AnyIndex: SpatialIndex + Send + Debug {}
impl<I: SpatialIndex + Send + Debug> AnyIndex for I {}

impl SpatialIndex for Box<dyn AnyIndex> {
    fn insert(
        &mut self,
        p: qicp_core::Point2<f64>,
    ) -> Result<qicp_core::PointId, qicp_core::IndexError> {
        (**self).insert(p)
    }
    fn clear(&mut self) {
        (**self).clear();
    }
    fn remove(&mut self, id: qicp_core::PointId) -> Option<bool> {
        (**self).remove(id)
    }
    fn revision(&self) -> Option<u64> {
        (**self).revision()
    }
    fn len(&self) -> usize {
        (**self).len()
    }
    fn points(&self) -> &[qicp_core::Point2<f64>] {
        (**self).points()
    }
    fn nearest_within(
        &self,
        q: &qicp_core::Point2<f64>,
        max_dist_sq: f64,
    ) -> Option<qicp_core::Neighbour> {
        (**self).nearest_within(q, max_dist_sq)
    }
    fn within_radius(
        &self,
        q: &qicp_core::Point2<f64>,
        radius: f64,
        out: &mut Vec<qicp_core::Neighbour>,
    ) {
        (**self).within_radius(q, radius, out);
    }
    fn k_nearest(&self, q: &qicp_core::Point2<f64>, k: usize, out: &mut Vec<qicp_core::Neighbour>) {
        (**self).k_nearest(q, k, out);
    }
    fn nearest_and_around(
        &self,
        q: &qicp_core::Point2<f64>,
        max_dist_sq: f64,
        slack: f64,
        max_reach: f64,
        out: &mut Vec<qicp_core::Neighbour>,
    ) -> (Option<qicp_core::Neighbour>, Option<f64>) {
        (**self).nearest_and_around(q, max_dist_sq, slack, max_reach, out)
    }
}

type IndexFactory = Arc<dyn Fn() -> Box<dyn AnyIndex> + Send + Sync>;

/// How an index is made: the built-in ones are compiled into each matcher (the hot loop stays
/// monomorphic); one registered at run time is reached through [`AnyIndex`].
#[derive(Clone)]
enum IndexMaker {
    QuadTree,
    KdTree,
    Dynamic(IndexFactory),
}

/// What a pipeline is built from: everything but the algorithm and the index.
#[derive(Debug)]
pub(crate) struct Assembly<'a> {
    pub kind: String,
    pub icp: IcpParams,
    pub policy: Box<dyn ReferencePolicy>,
    pub motion: MotionModel,
    pub validation: ValidationParams,
    pub correlative: CorrelativeParams,
    pub revisit: RevisitParams,
    pub laser: LaserNoise,
    pub index: &'a IndexEntry,
}

/// A registered algorithm without its type: what a [`MatcherConfig`] holds.
pub(crate) trait ErasedAlgorithm: Send + Sync {
    fn name(&self) -> &'static str;
    fn summary(&self) -> &'static str;
    fn parameters(&self) -> &'static [Param];
    fn icp_defaults(&self) -> IcpParams;
    /// Checks a user's section and returns the effective one (defaults filled in).
    fn effective(&self, section: &toml::Table) -> Result<toml::Table, ConfigError>;
    fn map_resolution(&self, section: &toml::Table, noise: &LaserNoise)
    -> Result<f64, ConfigError>;
    fn surface_band_sigmas(&self, section: &toml::Table) -> Result<f64, ConfigError>;
    fn min_novelty(&self, section: &toml::Table) -> Result<f64, ConfigError>;
    fn weighs_by_laser_noise(&self) -> bool;
    fn build(
        &self,
        section: &toml::Table,
        with: Assembly<'_>,
    ) -> Result<Box<dyn Odometry>, ConfigError>;
}

struct Registered<A>(PhantomData<fn() -> A>);

impl<A: Algorithm> Registered<A> {
    fn params(&self, section: &toml::Table) -> Result<A::Params, ConfigError> {
        let key = format!("matcher.{}", A::NAME);
        let params: A::Params = parse_section(&key, section, A::PARAMETERS)?;
        check_section(&key, &params, A::PARAMETERS)?;
        A::check(&params)?;
        Ok(params)
    }
}

fn assemble<M, I>(matcher: M, index: I, noise: LaserNoise, with: Assembly<'_>) -> Box<dyn Odometry>
where
    M: ScanMatcher + Send + Debug + 'static,
    I: SpatialIndex + Send + Debug + 'static,
{
    Box::new(
        Pipeline::new(with.kind, matcher, index, with.policy, noise)
            .with_motion_model(with.motion)
            .with_validation(with.validation, with.correlative)
            .with_revisit(with.revisit),
    )
}

impl<A: Algorithm> ErasedAlgorithm for Registered<A> {
    fn name(&self) -> &'static str {
        A::NAME
    }
    fn summary(&self) -> &'static str {
        A::SUMMARY
    }
    fn parameters(&self) -> &'static [Param] {
        A::PARAMETERS
    }
    fn icp_defaults(&self) -> IcpParams {
        A::icp_defaults()
    }
    fn effective(&self, section: &toml::Table) -> Result<toml::Table, ConfigError> {
        to_table(&self.params(section)?)
    }
    fn map_resolution(
        &self,
        section: &toml::Table,
        noise: &LaserNoise,
    ) -> Result<f64, ConfigError> {
        Ok(A::map_resolution(&self.params(section)?, noise))
    }
    fn surface_band_sigmas(&self, section: &toml::Table) -> Result<f64, ConfigError> {
        Ok(A::surface_band_sigmas(&self.params(section)?))
    }
    fn min_novelty(&self, section: &toml::Table) -> Result<f64, ConfigError> {
        Ok(A::min_novelty(&self.params(section)?))
    }
    fn weighs_by_laser_noise(&self) -> bool {
        A::WEIGHS_BY_LASER_NOISE
    }
    fn build(
        &self,
        section: &toml::Table,
        with: Assembly<'_>,
    ) -> Result<Box<dyn Odometry>, ConfigError> {
        let params = self.params(section)?;
        let noise = with.laser;
        let icp = with.icp;
        Ok(match &with.index.make {
            IndexMaker::QuadTree => assemble(
                A::matcher::<MutualNearest<QuadTree>>(icp, &params),
                QuadTree::default(),
                noise,
                with,
            ),
            IndexMaker::KdTree => assemble(
                A::matcher::<MutualNearest<KdTree>>(icp, &params),
                KdTree::default(),
                noise,
                with,
            ),
            IndexMaker::Dynamic(make) => {
                let index = make();
                assemble(
                    A::matcher::<MutualNearest<QuadTree>>(icp, &params),
                    index,
                    noise,
                    with,
                )
            }
        })
    }
}

/// Algorithms and indexes by name. Cheap to clone: entries are shared.
#[derive(Clone, Default)]
pub struct Registry {
    algorithms: Vec<Arc<dyn ErasedAlgorithm>>,
    indexes: Vec<IndexEntry>,
    references: Vec<ReferenceEntry>,
}

impl Debug for Registry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Registry")
            .field("algorithms", &self.algorithm_names())
            .field("indexes", &self.indexes)
            .field("references", &self.references)
            .finish()
    }
}

static BUILTIN: LazyLock<Registry> = LazyLock::new(|| {
    let mut r = Registry::default();
    r.register::<crate::idc::IdcAlgorithm>();
    r.register::<crate::wsm::WsmAlgorithm>();
    r.indexes.push(IndexEntry {
        name: "quadtree",
        prefix: "q",
        summary: "the paper's point quad tree (qicp_core::QuadTree)",
        make: IndexMaker::QuadTree,
    });
    r.indexes.push(IndexEntry {
        name: "kdtree",
        prefix: "kd",
        summary: "a kd-tree on kiddo (qicp_core::KdTree)",
        make: IndexMaker::KdTree,
    });
    r.register_index(
        "brute-force",
        "bf",
        "a plain list searched linearly: the oracle",
        || Box::new(BruteForce::default()),
    );
    r.references.push(ReferenceEntry::map());
    r.references.push(ReferenceEntry::scan());
    r
});

impl Registry {
    /// The built-in algorithms (`idc`, `wsm`), indexes (`quadtree`, `kdtree`, `brute-force`)
    /// and reference policies (`map`, `scan`).
    #[must_use]
    pub fn builtin() -> Self {
        BUILTIN.clone()
    }

    /// Registers algorithm `A` under [`Algorithm::NAME`], replacing one of that name.
    pub fn register<A: Algorithm>(&mut self) -> &mut Self {
        self.algorithms.retain(|a| a.name() != A::NAME);
        self.algorithms.push(Arc::new(Registered::<A>(PhantomData)));
        self
    }

    /// Registers an index made by `make` under `name`, with `prefix` for composed names
    /// (`<prefix>-wsm`). Matchers reach it through [`AnyIndex`] (one virtual call per query).
    pub fn register_index(
        &mut self,
        name: &'static str,
        prefix: &'static str,
        summary: &'static str,
        make: impl Fn() -> Box<dyn AnyIndex> + Send + Sync + 'static,
    ) -> &mut Self {
        self.indexes
            .retain(|i| i.name != name && i.prefix != prefix);
        self.indexes.push(IndexEntry {
            name,
            prefix,
            summary,
            make: IndexMaker::Dynamic(Arc::new(make)),
        });
        self
    }

    /// Registers a reference policy made by `make` (from the config's `[matcher.relevance]`)
    /// under `name`, replacing one of that name. Every algorithm and index can then be matched
    /// against it: `[matcher] algorithm = "wsm"`, `reference = "<name>"`, or the composed name
    /// `wsm+<name>` (`wsm+<name>@kdtree` in another index).
    ///
    /// Refused: an empty name, one holding `+`, `@` or `-` (composed names use them), and the
    /// built-in `map` and `scan`, whose composed names are the presets.
    pub fn register_reference(
        &mut self,
        name: &'static str,
        summary: &'static str,
        make: impl Fn(&Relevance) -> Box<dyn ReferencePolicy> + Send + Sync + 'static,
    ) -> Result<&mut Self, ConfigError> {
        if name.is_empty() || name.contains(['+', '@', '-']) || is_builtin(name) {
            return Err(ConfigError::invalid(
                "matcher.reference",
                format!(
                    "cannot register `{name}`: a policy's name is not empty, holds no `+`, `@` \
                     or `-`, and is not a built-in one ({MAP}, {SCAN})"
                ),
            ));
        }
        self.references.retain(|r| r.name() != name);
        self.references
            .push(ReferenceEntry::new(name, summary, make));
        Ok(self)
    }

    /// The registered reference policies.
    #[must_use]
    pub fn references(&self) -> &[ReferenceEntry] {
        &self.references
    }

    /// Names of the registered algorithms, in registration order.
    #[must_use]
    pub fn algorithm_names(&self) -> Vec<&'static str> {
        self.algorithms.iter().map(|a| a.name()).collect()
    }

    /// The registered indexes.
    #[must_use]
    pub fn indexes(&self) -> &[IndexEntry] {
        &self.indexes
    }

    /// The declared parameters of algorithm `name`, with one-line summary.
    #[must_use]
    pub fn parameters(&self, name: &str) -> Option<(&'static str, &'static [Param])> {
        self.algorithm(name)
            .ok()
            .map(|a| (a.summary(), a.parameters()))
    }

    /// Every composed name: each algorithm scan to scan, then against a map in each index.
    #[must_use]
    pub fn names(&self) -> Vec<String> {
        let mut out = self
            .algorithm_names()
            .iter()
            .map(|a| a.to_string())
            .collect::<Vec<_>>();
        for i in &self.indexes {
            out.extend(
                self.algorithms
                    .iter()
                    .map(|a| format!("{}-{}", i.prefix, a.name())),
            );
        }
        for r in self.references.iter().filter(|r| !is_builtin(r.name())) {
            out.extend(
                self.algorithms
                    .iter()
                    .map(|a| format!("{}+{}", a.name(), r.name())),
            );
        }
        out
    }

    pub(crate) fn reference(&self, name: &str) -> Result<ReferenceEntry, ConfigError> {
        self.references
            .iter()
            .find(|r| r.name() == name)
            .cloned()
            .ok_or_else(|| {
                ConfigError::invalid(
                    "matcher.reference",
                    format!(
                        "unknown reference `{name}`; known: {}",
                        self.references
                            .iter()
                            .map(ReferenceEntry::name)
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                )
            })
    }

    pub(crate) fn algorithm(&self, name: &str) -> Result<Arc<dyn ErasedAlgorithm>, ConfigError> {
        self.algorithms
            .iter()
            .find(|a| a.name() == name)
            .cloned()
            .ok_or_else(|| {
                ConfigError::invalid(
                    "matcher.algorithm",
                    format!(
                        "unknown algorithm `{name}`; known: {}",
                        self.algorithm_names().join(", ")
                    ),
                )
            })
    }

    pub(crate) fn index(&self, name: &str) -> Result<IndexEntry, ConfigError> {
        self.indexes
            .iter()
            .find(|i| i.name == name)
            .cloned()
            .ok_or_else(|| {
                ConfigError::invalid(
                    "matcher.index",
                    format!(
                        "unknown index `{name}`; known: {}",
                        self.indexes
                            .iter()
                            .map(|i| i.name)
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                )
            })
    }

    pub(crate) fn is_algorithm(&self, name: &str) -> bool {
        self.algorithms.iter().any(|a| a.name() == name)
    }

    /// The axes of a composed name: `wsm` → (wsm, scan, quadtree), `kd-wsm` → (wsm, map, kdtree),
    /// `wsm@kdtree` → (wsm, scan, kdtree), `wsm+window` → (wsm, window, quadtree) and
    /// `wsm+window@kdtree` → (wsm, window, kdtree) for a registered policy `window`.
    pub fn resolve(
        &self,
        name: &str,
    ) -> Result<(&'static str, ReferenceEntry, &'static str), ConfigError> {
        if let Ok(a) = self.algorithm(name) {
            return Ok((a.name(), ReferenceEntry::scan(), "quadtree"));
        }
        let (head, index) = match name.split_once('@') {
            Some((head, index)) => (head, self.index(index).ok()),
            None => (name, self.index("quadtree").ok()),
        };
        if let Some(i) = index {
            if let Some((algorithm, reference)) = head.rsplit_once('+')
                && let (Ok(a), Ok(r)) = (self.algorithm(algorithm), self.reference(reference))
                && !is_builtin(r.name())
            {
                return Ok((a.name(), r, i.name));
            }
            if name.contains('@')
                && let Ok(a) = self.algorithm(head)
            {
                return Ok((a.name(), ReferenceEntry::scan(), i.name));
            }
        }
        for i in &self.indexes {
            if let Some(rest) = name
                .strip_prefix(i.prefix)
                .and_then(|r| r.strip_prefix('-'))
                && let Ok(a) = self.algorithm(rest)
            {
                return Ok((a.name(), ReferenceEntry::map(), i.name));
            }
        }
        let hint = match name.rsplit_once('+').map(|(a, r)| (a, r.split('@').next())) {
            Some((a, Some(MAP))) => format!(" (a map is the `<prefix>-` form: q-{a})"),
            Some((a, Some(SCAN))) => format!(" (scan to scan is the plain name: {a})"),
            _ => String::new(),
        };
        Err(ConfigError::invalid(
            "matcher.kind",
            format!(
                "unknown kind `{name}`{hint}; known: {} (and `<algorithm>@<index>` scan to scan)",
                self.names().join(", ")
            ),
        ))
    }

    /// The name composed of three axes: the inverse of [`resolve`](Self::resolve). A
    /// scan-to-scan matcher over an index other than the quad tree is `<algorithm>@<index>`;
    /// a registered policy other than `map` and `scan` is `<algorithm>+<reference>`, with
    /// `@<index>` beyond the quad tree.
    #[must_use]
    pub fn compose(algorithm: &str, reference: &ReferenceEntry, index: &IndexEntry) -> String {
        let at = if index.name == "quadtree" {
            String::new()
        } else {
            format!("@{}", index.name)
        };
        match reference.name() {
            MAP => format!("{}-{algorithm}", index.prefix),
            SCAN => format!("{algorithm}{at}"),
            other => format!("{algorithm}+{other}{at}"),
        }
    }

    /// The defaults of a composed name (`"q-wsm"`), every section filled in.
    pub fn config(&self, name: &str) -> Result<MatcherConfig, ConfigError> {
        let (algorithm, reference, index) = self.resolve(name)?;
        MatcherConfig::from_axes(self, algorithm, reference, index)
    }

    /// Parses the `[matcher]` table of a TOML document and validates it.
    pub fn parse(&self, text: &str) -> Result<MatcherConfig, ConfigError> {
        MatcherConfig::parse_with(self, text)
    }
}
