//! A reference policy from outside the crate, through the public API only: registered by
//! name, it composes with every algorithm and index, parses from TOML, round-trips, and drives
//! a pipeline that keeps what the policy says.

use qicp_core::{Pose2, Record, Scan, testdata::SyntheticWorld};
use qicp_matchers::{
    Matched, MatcherConfig, ReferenceEntry, ReferencePolicy, ReferenceStore, Registry, Relevance,
};
use std::collections::VecDeque;

/// A local map of the latest `keep` scans that moved past the relevance thresholds, in the
/// world frame, rebuilt on each one.
#[derive(Debug)]
struct Recent {
    relevance: Relevance,
    keep: usize,
    scans: VecDeque<(Scan, Pose2)>,
}

impl ReferencePolicy for Recent {
    fn is_map(&self) -> bool {
        false
    }

    fn update(&mut self, reference: &mut dyn ReferenceStore, m: &Matched<'_>) -> bool {
        let relevant = self
            .scans
            .back()
            .is_none_or(|(_, last)| self.relevance.is_relevant(&last.between(&m.laser)));
        if !relevant || m.scan.valid_count() < 3 {
            return false;
        }
        self.scans.push_back((m.scan.clone(), m.laser));
        if self.scans.len() > self.keep {
            self.scans.pop_front();
        }
        reference.clear();
        self.scans
            .iter()
            .all(|(scan, pose)| reference.insert_scan(scan, pose, None))
    }
}

fn recent(relevance: &Relevance) -> Box<dyn ReferencePolicy> {
    Box::new(Recent {
        relevance: *relevance,
        keep: 2,
        scans: VecDeque::new(),
    })
}

fn registry() -> Registry {
    let mut registry = Registry::builtin();
    registry
        .register_reference("recent", "against the latest two relevant scans", recent)
        .expect("a new name");
    registry
}

#[test]
fn a_registered_reference_policy_composes_with_every_algorithm_and_index() {
    let registry = registry();
    let names = registry.names();
    for name in ["idc+recent", "wsm+recent"] {
        assert!(names.iter().any(|n| n == name), "{name} in {names:?}");
    }
    for name in ["wsm+recent", "idc+recent@kdtree", "wsm+recent@brute-force"] {
        let config = registry.config(name).expect(name);
        assert_eq!(config.kind(), name);
        assert_eq!(config.reference.name(), "recent");
        assert!(!config.reference.is_map());
        assert_eq!(config.build().expect("builds").kind(), name);
    }
    // From the axes, and back through the effective TOML.
    let config = registry
        .parse("[matcher]\nalgorithm = \"wsm\"\nreference = \"recent\"\nindex = \"kdtree\"\n")
        .expect("the axes resolve");
    assert_eq!(config.kind(), "wsm+recent@kdtree");
    assert_eq!(
        registry.parse(&config.to_toml()).expect("round trip"),
        config
    );
    // The built-in registry does not know it, and says which it knows.
    let e = Registry::builtin()
        .parse("[matcher]\nalgorithm = \"wsm\"\nreference = \"recent\"\n")
        .expect_err("unknown to the built-in registry")
        .to_string();
    assert!(
        e.contains("matcher.reference") && e.contains("map, scan"),
        "{e}"
    );
    // The presets keep their names: a built-in policy is never composed with `+`, nor
    // replaced, and a name that composed names could not parse is refused.
    let e = registry
        .config("wsm+map")
        .expect_err("a preset's axes")
        .to_string();
    assert!(e.contains("q-wsm"), "the error names the preset: {e}");
    let mut other = Registry::builtin();
    for name in ["map", "scan", "", "last-two", "a+b", "a@b"] {
        let e = other
            .register_reference(name, "refused", recent)
            .err()
            .unwrap_or_else(|| panic!("`{name}` must be refused"));
        assert!(e.to_string().contains("matcher.reference"), "{e}");
    }
    assert_eq!(
        registry.config("q-wsm").expect("preset").reference,
        ReferenceEntry::map()
    );
}

/// The policy's pipeline follows a slipping drive through a room and holds at most the two
/// scans the policy keeps.
#[test]
fn a_pipeline_keeps_the_reference_its_registered_policy_says() {
    let config: MatcherConfig = registry().config("wsm+recent").expect("composed");
    let mut pipeline = config.build().expect("builds");
    let room = SyntheticWorld::room();
    let mut held = Vec::new();
    let mut most_beams = 0;
    for k in 0..40 {
        let truth = Pose2::new(0.05 * k as f64, 0.02 * k as f64, 0.01 * k as f64);
        // Wheels that slip by 1 cm per step: odometry alone ends 0.4 m off.
        let odometry = truth * Pose2::new(0.01 * k as f64, 0.0, 0.0);
        let scan = room.scan(&truth, 0.005, k as u64);
        most_beams = most_beams.max(scan.valid_count());
        let estimate = pipeline.process(&Record {
            scan,
            odometry,
            truth: None,
            laser_offset: Pose2::IDENTITY,
        });
        assert!(
            estimate.pose.distance(&truth) < 0.03,
            "scan {k}: {:?} against {truth:?}",
            estimate.pose
        );
        assert!(pipeline.reference_points().len() <= 2 * most_beams);
        held.push(pipeline.reference_points().len());
    }
    // Relevant scans replaced the reference as the robot moved (0.25 m or 5° apart).
    assert!(held.windows(2).any(|w| w[0] != w[1]), "{held:?}");
}
