//! Re-anchoring on a revisit, on a room whose map holds an old copy and a drifted recent one:
//! a match that fits the recent copy is moved back onto the old one, and a map without drift
//! is left alone (the old map vouches for its match).

use qicp_core::testdata::SyntheticWorld;
use qicp_core::{MutualNearest, Pose2, QuadTree, Reference, ScanMatcher, SpatialIndex};
use qicp_matchers::revisit::AGREE_XY;
use qicp_matchers::{IcpParams, Registry, Revisit, RevisitParams, Wsm, WsmParams};

/// Where the robot sees the room from at scan `k`.
fn pose(k: usize) -> Pose2 {
    Pose2::new(
        -1.5 + 0.2 * k as f64,
        -0.5 + 0.05 * k as f64,
        0.1 * k as f64,
    )
}

/// A map of the room: four scans laid at their true poses (the old map), then `recent` scans
/// laid `drift` off (what a robot lays that comes back with that much drift), the look-ups
/// told of each insertion.
fn map(drift: Pose2, recent: usize, revisit: &mut Revisit) -> Reference<QuadTree> {
    let mut reference = Reference::new(QuadTree::default());
    lay(&mut reference, drift, 0..OLD + recent, Some(revisit));
    reference
}

/// Lays scans `ks` into `reference` in that order: scan k < [`OLD`] at its true pose (the old
/// map), scan k ≥ `OLD` as a view of scan k mod `OLD` laid `drift` off; the look-ups, if
/// given, told of each insertion.
fn lay(
    reference: &mut Reference<QuadTree>,
    drift: Pose2,
    ks: impl IntoIterator<Item = usize>,
    mut revisit: Option<&mut Revisit>,
) {
    let room = SyntheticWorld::room();
    for k in ks {
        let scan = room.scan(&pose(k % OLD), 0.005, k as u64 + 1);
        let laid = if k < OLD {
            pose(k)
        } else {
            drift * pose(k % OLD)
        };
        reference.insert_scan(&scan, &laid, None).expect("finite");
        if let Some(r) = revisit.as_deref_mut() {
            r.inserted(reference.index().len());
        }
    }
}

/// Scans of the old map.
const OLD: usize = 4;

/// Look-ups at every scan, for which the newest three insertions are recent.
fn look_ups() -> Revisit {
    Revisit::new(RevisitParams {
        age_scans: 4,
        every: 1,
        ..RevisitParams::default()
    })
}

#[test]
fn a_match_on_a_drifted_copy_of_the_room_is_reanchored_to_the_old_map() {
    let drift = Pose2::new(0.45, -0.3, 1.5f64.to_radians());
    let mut revisit = look_ups();
    let reference = map(drift, 3, &mut revisit);
    let truth = pose(4);
    let scan = SyntheticWorld::room().scan(&truth, 0.005, 99);
    // The match a boosted matcher makes: the scan fits the recent copy, drift off.
    let drifted = drift * truth;
    let proposal = revisit
        .propose(&reference, scan.points(), &drifted)
        .expect("the old map explains the scan far better near the truth");
    assert!(
        proposal.start.distance(&truth) < 0.08,
        "{:?} against {truth:?}",
        proposal.start
    );
    // ICP from there, against the whole map, lands on the old copy and is confirmed.
    let mut wsm = Wsm::<MutualNearest<QuadTree>>::new(IcpParams::default(), WsmParams::default());
    let again = wsm.match_with_prior(&reference, &scan, proposal.start, None);
    assert!(again.fallback.is_none(), "{again:?}");
    assert!(
        again.pose.distance(&truth) < 0.03,
        "{:?} against {truth:?}",
        again.pose
    );
    assert!(revisit.confirms(&reference, scan.points(), &again.pose, &proposal));
    // A room's walls pin it: its σ lies well within the look-ups' tolerance.
    assert!(again.position_sigma() < 0.2 * AGREE_XY, "{again:?}");
    assert!(Revisit::well_determined(&again));
    // The drifted pose itself is not confirmed in the old map.
    assert!(!revisit.confirms(&reference, scan.points(), &drifted, &proposal));
}

#[test]
fn a_map_without_drift_is_left_alone() {
    let mut revisit = look_ups();
    let reference = map(Pose2::IDENTITY, 3, &mut revisit);
    let truth = pose(4);
    let scan = SyntheticWorld::room().scan(&truth, 0.005, 99);
    assert_eq!(revisit.propose(&reference, scan.points(), &truth), None);
    // The old map explained the match nearly whole: it vouches for it, once, and the room's
    // walls pin it.
    let vouch = revisit.take_vouched().expect("vouched for");
    assert!(revisit.take_vouched().is_none());
    assert!(revisit.pins(&reference, &vouch));
}

/// In a corridor with no feature along it the old walls explain a match slid along it as
/// well: they vouch for the match, but do not pin it.
#[test]
fn an_old_map_of_a_featureless_corridor_vouches_for_a_match_but_does_not_pin_it() {
    let corridor = SyntheticWorld::featureless_corridor();
    let at = |k: usize| Pose2::new(0.5 * k as f64, 0.1, 0.02 * k as f64);
    let mut revisit = look_ups();
    let mut reference = Reference::new(QuadTree::default());
    for k in 0..OLD + 3 {
        let scan = corridor.scan(&at(k % OLD), 0.005, k as u64 + 1);
        reference
            .insert_scan(&scan, &at(k % OLD), None)
            .expect("finite");
        revisit.inserted(reference.index().len());
    }
    let truth = at(1);
    let scan = corridor.scan(&truth, 0.005, 99);
    assert_eq!(revisit.propose(&reference, scan.points(), &truth), None);
    let vouch = revisit.take_vouched().expect("vouched for");
    assert!(!revisit.pins(&reference, &vouch));
}

#[test]
fn the_old_map_vouches_only_for_a_match_it_explains_nearly_whole() {
    let drift = Pose2::new(0.45, -0.3, 1.5f64.to_radians());
    let mut revisit = look_ups();
    let reference = map(drift, 3, &mut revisit);
    let truth = pose(4);
    let scan = SyntheticWorld::room().scan(&truth, 0.005, 99);
    assert!(
        revisit
            .propose(&reference, scan.points(), &(drift * truth))
            .is_some()
    );
    assert!(revisit.take_vouched().is_none(), "a drifted match");
    // A scan not due for a look-up is vouched for by none.
    let mut sparse = Revisit::new(RevisitParams {
        every: 2,
        ..*look_ups().params()
    });
    let reference = map(Pose2::IDENTITY, 3, &mut sparse);
    assert_eq!(sparse.propose(&reference, scan.points(), &truth), None);
    assert!(sparse.take_vouched().is_none(), "not looked up");
    assert_eq!(sparse.propose(&reference, scan.points(), &truth), None);
    assert!(sparse.take_vouched().is_some(), "looked up");
    // Without `deform` no spread reads a vouch, and none is kept (nor the scan copied).
    let mut jumps = Revisit::new(RevisitParams {
        deform: false,
        ..*look_ups().params()
    });
    let reference = map(Pose2::IDENTITY, 3, &mut jumps);
    assert_eq!(jumps.propose(&reference, scan.points(), &truth), None);
    assert!(jumps.take_vouched().is_none(), "kept without deform");
}

#[test]
fn a_map_younger_than_its_age_is_not_looked_up() {
    let drift = Pose2::new(0.45, -0.3, 0.0);
    let mut revisit = look_ups();
    // Without the recent copy, the map's scans are too few to be old at an age of four.
    let reference = map(drift, 0, &mut revisit);
    let truth = pose(4);
    let scan = SyntheticWorld::room().scan(&truth, 0.005, 99);
    assert_eq!(
        revisit.propose(&reference, scan.points(), &(drift * truth)),
        None
    );
    // Switched off, a map old enough is not looked up either.
    let mut off = Revisit::new(RevisitParams {
        enabled: false,
        ..*look_ups().params()
    });
    let reference = map(drift, 3, &mut off);
    assert_eq!(
        off.propose(&reference, scan.points(), &(drift * truth)),
        None
    );
}

#[test]
fn revisit_values_out_of_range_are_refused_with_their_key() {
    for (key, value) in [
        ("max_miss", "1.5"),
        ("min_gain", "-0.1"),
        ("min_gain", "0"),
        ("window_xy", "0"),
        ("window_deg", "200"),
        ("age_scans", "0"),
        ("every", "0"),
        ("confirmations", "0"),
        ("confirm_gap", "1001"),
    ] {
        let text = format!("[matcher]\nkind = \"q-wsm\"\n[matcher.revisit]\n{key} = {value}\n");
        let err = Registry::builtin()
            .parse(&text)
            .and_then(|c| c.build().map(|_| ()))
            .expect_err(key);
        assert!(
            err.to_string().contains(&format!("matcher.revisit.{key}")),
            "{key}: {err}"
        );
    }
}

/// The re-anchored pose a look-up at `drifted` finds: the proposal refined by ICP against the
/// whole map.
fn reanchored(revisit: &mut Revisit, reference: &Reference<QuadTree>, drifted: &Pose2) -> Pose2 {
    let scan = SyntheticWorld::room().scan(&pose(4), 0.005, 99);
    let proposal = revisit
        .propose(reference, scan.points(), drifted)
        .expect("a proposal");
    let mut wsm = Wsm::<MutualNearest<QuadTree>>::new(IcpParams::default(), WsmParams::default());
    let again = wsm.match_with_prior(reference, &scan, proposal.start, None);
    assert!(revisit.confirms(reference, scan.points(), &again.pose, &proposal));
    again.pose
}

#[test]
fn a_reanchoring_is_taken_once_look_ups_close_together_agree_on_it() {
    let drift = Pose2::new(0.45, -0.3, 1.5f64.to_radians());
    let drifted = drift * pose(4);
    let scan = SyntheticWorld::room().scan(&pose(4), 0.005, 99);
    // A look-up that finds no pose: the scan at its true pose fits the old map.
    let finds_nothing = |revisit: &mut Revisit, reference: &Reference<QuadTree>| {
        assert_eq!(revisit.propose(reference, scan.points(), &pose(4)), None);
    };
    let mut revisit = look_ups();
    let reference = map(drift, 3, &mut revisit);
    // The first look-up finds it; the default asks for a second that agrees.
    let found = reanchored(&mut revisit, &reference, &drifted);
    assert!(!revisit.corroborated(&drifted, &found));
    let again = reanchored(&mut revisit, &reference, &drifted);
    assert!(revisit.corroborated(&drifted, &again), "agreeing look-ups");
    // A second look-up whose correction lands elsewhere (aliasing) starts a new run.
    let found = reanchored(&mut revisit, &reference, &drifted);
    assert!(!revisit.corroborated(&drifted, &found));
    let elsewhere = Pose2::new(0.3, 0.0, 0.0) * reanchored(&mut revisit, &reference, &drifted);
    assert!(!revisit.corroborated(&drifted, &elsewhere), "0.3 m apart");
    // Up to `confirm_gap` look-ups that find nothing between two that agree neither confirm
    // nor break the run…
    let gap = revisit.params().confirm_gap;
    assert_eq!(gap, 8);
    let found = reanchored(&mut revisit, &reference, &drifted);
    assert!(!revisit.corroborated(&drifted, &found));
    for _ in 0..gap {
        finds_nothing(&mut revisit, &reference);
    }
    let found = reanchored(&mut revisit, &reference, &drifted);
    assert!(
        revisit.corroborated(&drifted, &found),
        "{gap} look-ups between"
    );
    // … one more does.
    let found = reanchored(&mut revisit, &reference, &drifted);
    assert!(!revisit.corroborated(&drifted, &found));
    for _ in 0..=gap {
        finds_nothing(&mut revisit, &reference);
    }
    let found = reanchored(&mut revisit, &reference, &drifted);
    assert!(
        !revisit.corroborated(&drifted, &found),
        "{} look-ups between",
        gap + 1
    );
    // `confirm_gap = 0` asks for look-ups strictly in a row.
    let mut in_a_row = Revisit::new(RevisitParams {
        confirm_gap: 0,
        ..*look_ups().params()
    });
    let reference = map(drift, 3, &mut in_a_row);
    let found = reanchored(&mut in_a_row, &reference, &drifted);
    assert!(!in_a_row.corroborated(&drifted, &found));
    finds_nothing(&mut in_a_row, &reference);
    let found = reanchored(&mut in_a_row, &reference, &drifted);
    assert!(!in_a_row.corroborated(&drifted, &found), "not in a row");
    let found = reanchored(&mut in_a_row, &reference, &drifted);
    assert!(in_a_row.corroborated(&drifted, &found));
    // The gap counts look-ups, one every `every` matched scans, not matched scans: at
    // `every` = 5 and `confirm_gap` = 1 two look-ups agree across one that finds nothing
    // (ten matched scans apart), not across two (fifteen).
    let mut sparse = Revisit::new(RevisitParams {
        every: 5,
        confirm_gap: 1,
        ..*look_ups().params()
    });
    let reference = map(drift, 3, &mut sparse);
    let matched_scans = |revisit: &mut Revisit, n: usize| {
        for _ in 0..n {
            finds_nothing(revisit, &reference);
        }
    };
    matched_scans(&mut sparse, 4);
    let found = reanchored(&mut sparse, &reference, &drifted);
    assert!(!sparse.corroborated(&drifted, &found));
    matched_scans(&mut sparse, 9);
    let found = reanchored(&mut sparse, &reference, &drifted);
    assert!(sparse.corroborated(&drifted, &found), "one look-up between");
    matched_scans(&mut sparse, 4);
    let found = reanchored(&mut sparse, &reference, &drifted);
    assert!(!sparse.corroborated(&drifted, &found));
    matched_scans(&mut sparse, 14);
    let found = reanchored(&mut sparse, &reference, &drifted);
    assert!(
        !sparse.corroborated(&drifted, &found),
        "two look-ups between"
    );
    // One confirmation takes the first.
    let mut first = Revisit::new(RevisitParams {
        confirmations: 1,
        ..*look_ups().params()
    });
    let reference = map(drift, 3, &mut first);
    let found = reanchored(&mut first, &reference, &drifted);
    assert!(first.corroborated(&drifted, &found));
}

#[test]
fn look_ups_built_with_an_age_of_zero_do_not_panic() {
    // Built directly, the parameters are not validated; an age of 0 is taken as 1.
    let mut revisit = Revisit::new(RevisitParams {
        age_scans: 0,
        every: 1,
        ..RevisitParams::default()
    });
    assert_eq!(revisit.params().age_scans, 1);
    // Every scan but the newest is old: the drifted copy is old map too, and fits the match.
    assert_eq!(propose_on_a_drifted_room(&mut revisit), None);
}

/// The look-ups' proposal for scan 4 of the room, matched 1.5° and half a metre off, over a
/// map of the room's four scans and three laid that far off.
fn propose_on_a_drifted_room(revisit: &mut Revisit) -> Option<qicp_matchers::Proposal> {
    let drift = Pose2::new(0.45, -0.3, 1.5f64.to_radians());
    let reference = map(drift, 3, revisit);
    let truth = pose(4);
    let scan = SyntheticWorld::room().scan(&truth, 0.005, 99);
    revisit.propose(&reference, scan.points(), &(drift * truth))
}

#[test]
fn a_map_given_new_ids_is_not_looked_up_until_it_is_old_again() {
    let drift = Pose2::new(0.45, -0.3, 1.5f64.to_radians());
    let mut revisit = look_ups();
    let mut reference = map(drift, 3, &mut revisit);
    let truth = pose(4);
    let scan = SyntheticWorld::room().scan(&truth, 0.005, 99);
    let drifted = drift * truth;
    assert!(
        revisit
            .propose(&reference, scan.points(), &drifted)
            .is_some()
    );
    // The map laid again, the drifted copy first (twice) and the old one after: it is longer
    // than before, but the ids the look-ups took for old now hold the drifted copy alone.
    let renumbered = reference.renumberings();
    reference.clear();
    let drifted_twice_then_old = (OLD..OLD + 3).chain(OLD..OLD + 3).chain(0..OLD);
    lay(&mut reference, drift, drifted_twice_then_old, None);
    assert!(reference.renumberings() > renumbered);
    // Ages kept across the renumbering take the drifted copy for the old map, and would move
    // the right match onto it.
    let mut stale = revisit.clone();
    stale.inserted(reference.index().len());
    assert!(stale.propose(&reference, scan.points(), &truth).is_some());
    // Told of it, the look-ups wait until the map is old again…
    revisit.renumbered();
    revisit.inserted(reference.index().len());
    assert_eq!(revisit.propose(&reference, scan.points(), &truth), None);
    // … and look up again once the map is old enough: laid afresh as at the start (the old
    // copy, then the drifted one), the drifted match is proposed back onto the old copy.
    reference.clear();
    revisit.renumbered();
    lay(&mut reference, drift, 0..OLD + 3, Some(&mut revisit));
    assert!(
        revisit
            .propose(&reference, scan.points(), &drifted)
            .is_some(),
        "look-ups resume"
    );
}

#[test]
fn default_look_ups_search_the_revisit_window_not_the_correlative_one() {
    // A derived default took the correlative search's 0.5 m and 25°, not the 1 m and 3° its
    // parameters report.
    let derived = format!("{:?}", Revisit::default());
    let built = format!("{:?}", Revisit::new(RevisitParams::default()));
    assert_eq!(derived, built);
    assert!(built.contains("window_deg: 3.0"), "{built}");
}

#[test]
fn look_ups_built_with_the_largest_age_count_insertions_without_overflow() {
    let mut revisit = Revisit::new(RevisitParams {
        age_scans: usize::MAX,
        every: 1,
        ..RevisitParams::default()
    });
    // No map is ever that old.
    assert_eq!(propose_on_a_drifted_room(&mut revisit), None);
}
