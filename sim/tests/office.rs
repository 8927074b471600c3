//! Office floors drawn from a seed (`configs/worlds/office.toml`): the corridor loop of
//! `corridor.toml` with its doorways moved along their walls, some closed, and furniture in the
//! rooms. The plain corridor stays one layout; the corridor itself stays clear.

use qicp_sim::{SimConfig, World};
use std::path::PathBuf;

fn shipped(name: &str) -> SimConfig {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../configs/worlds")
        .join(name);
    SimConfig::load(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The office floor of `seed`, its corridor section changed by `edit`.
fn office(seed: u64, edit: impl Fn(&mut qicp_sim::config::CorridorConfig)) -> World {
    let mut cfg = shipped("office.toml");
    cfg.world.seed = seed;
    edit(
        cfg.world
            .corridor
            .as_mut()
            .expect("office.toml has [world.corridor]"),
    );
    cfg.validate().expect("valid");
    World::build(&cfg).expect("builds")
}

/// The open stretches, as (start, end) in x, of the line y = `y` from `x0` to `x1`, sampled
/// every centimetre.
fn gaps(world: &World, y: f64, x0: f64, x1: f64) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    let mut open: Option<f64> = None;
    let steps = ((x1 - x0) / 0.01).round() as usize;
    for k in 0..=steps {
        let x = x0 + (x1 - x0) * k as f64 / steps as f64;
        let free = world.signed_distance(&qicp_core::Point2::new(x, y)) > 0.0;
        match (free, open) {
            (true, None) => open = Some(x),
            (false, Some(start)) => {
                out.push((start, x));
                open = None;
            }
            _ => {}
        }
    }
    if let Some(start) = open {
        out.push((start, x1));
    }
    out
}

#[test]
fn the_plain_corridor_is_one_layout_whatever_the_seed() {
    let build = |seed| {
        let mut cfg = shipped("corridor.toml");
        cfg.world.seed = seed;
        World::build(&cfg).expect("builds").obstacles
    };
    assert_eq!(build(7), build(8));
}

#[test]
fn each_seed_draws_another_office_floor_with_furniture() {
    let plain = World::build(&shipped("corridor.toml")).expect("builds");
    let floors: Vec<World> = (7..13).map(|seed| office(seed, |_| {})).collect();
    for (i, a) in floors.iter().enumerate() {
        assert!(
            a.obstacles.len() > plain.obstacles.len(),
            "world {}: no furniture",
            7 + i
        );
        for b in &floors[i + 1..] {
            assert_ne!(a.obstacles, b.obstacles);
        }
        // The route is the corridor's: the layout draws leave it alone.
        assert_eq!(a.route, plain.route);
    }
}

#[test]
fn doorways_stay_inside_their_rooms_and_closed_ones_leave_a_bare_wall() {
    // Side 0's corridor wall on the outer rooms' side: y = 5 (outer_room_depth), from x = 5 to
    // 25 (four rooms of 5 m, partitions at x = 5, 10, 15, 20, 25). The wall is 0.1 m thick.
    let (y, partitions) = (5.0, [5.0, 10.0, 15.0, 20.0, 25.0]);
    let mut moved = 0;
    for seed in 7..17 {
        let world = office(seed, |c| c.closed_doors = 0.0);
        let open = gaps(&world, y, 5.0, 25.0);
        assert_eq!(open.len(), 4, "seed {seed}: {open:?}");
        for ((a, b), room) in open.iter().zip(partitions.windows(2)) {
            // 1 m doorways, less the wall's half thickness by which each segment reaches into
            // it.
            assert!((b - a - 0.9).abs() < 0.03, "seed {seed}: doorway {a}-{b}");
            // Clear of the partitions' walls (0.05 m each side of their centre lines).
            assert!(
                *a > room[0] + 0.05 && *b < room[1] - 0.05,
                "seed {seed}: {a}-{b}"
            );
            if ((a + b) / 2.0 - (room[0] + room[1]) / 2.0).abs() > 0.2 {
                moved += 1;
            }
        }
        let closed = office(seed, |c| c.closed_doors = 1.0);
        assert!(gaps(&closed, y, 5.0, 25.0).is_empty(), "seed {seed}");
    }
    // Shifts up to 1.5 m: most of the forty doorways leave their room's middle.
    assert!(moved > 20, "only {moved} of 40 doorways moved");
}

#[test]
fn nothing_stands_in_the_corridor() {
    // The corridor ring: between the outer rooms' wall (5 m from the floor's edge) and the
    // inner rooms' (7.4 m), walls 0.1 m thick, so free from 5.05 to 7.35 m; furniture, as
    // much of it as a room may hold, stays in the rooms.
    for seed in 7..12 {
        let world = office(seed, |c| c.furniture = 20);
        for i in 0..=198 {
            for j in 0..=198 {
                let (x, y) = (5.1 + 0.1 * f64::from(i), 5.1 + 0.1 * f64::from(j));
                let in_core = (7.35..=22.65).contains(&x) && (7.35..=22.65).contains(&y);
                if !in_core {
                    let d = world.signed_distance(&qicp_core::Point2::new(x, y));
                    assert!(d > 0.0, "seed {seed}: ({x:.1}, {y:.1}) inside an obstacle");
                }
            }
        }
    }
}
