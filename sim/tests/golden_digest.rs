//! Determinism: the same configuration and seed give bit-identical records, pinned by a golden
//! digest of a short park drive and a short corridor drive (FNV-1a over the bits of every
//! timestamp, pose and range; see `qicp_sim::digest`). rapier2d runs with
//! `enhanced-determinism`. If a deliberate change to the simulator moves these digests, update
//! them in the same commit and say why.

use qicp_sim::{SimConfig, Simulation, digest};
use std::path::PathBuf;

const PARK_30_SCANS: u64 = 0x61e7_d379_e38e_07be;
const SPARSE_PARK_30_SCANS: u64 = 0x37ff_6f69_f6bb_521c;
const CORRIDOR_40_SCANS: u64 = 0x5645_2517_c265_5b4d;

fn short(name: &str, scans: usize) -> SimConfig {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../configs/worlds")
        .join(name);
    let mut cfg = SimConfig::load(&path).expect("shipped config");
    cfg.drive.max_scans = Some(scans);
    cfg
}

fn digest_of(cfg: SimConfig) -> u64 {
    let (records, _, _) = Simulation::run(cfg).expect("runs");
    digest(&records)
}

#[test]
fn the_same_config_and_seed_give_identical_records() {
    let a = digest_of(short("park.toml", 30));
    let b = digest_of(short("park.toml", 30));
    assert_eq!(a, b);
    let mut other = short("park.toml", 30);
    other.drive.seed += 1;
    assert_ne!(digest_of(other), a, "the noise seed must matter");
}

#[test]
fn golden_digests_of_the_shipped_drives() {
    let park = digest_of(short("park.toml", 30));
    let sparse = digest_of(short("park-sparse.toml", 30));
    let corridor = digest_of(short("corridor.toml", 40));
    assert_eq!(
        (park, sparse, corridor),
        (PARK_30_SCANS, SPARSE_PARK_30_SCANS, CORRIDOR_40_SCANS),
        "digests moved: park {park:#018x}, sparse park {sparse:#018x}, corridor {corridor:#018x}"
    );
}
