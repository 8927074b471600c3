//! The Intel log's files for command-line tests, read where they are (`../shared/data/intel/`,
//! never copied into the project).

use std::path::PathBuf;

/// The path of `name` in the Intel data directory, as a command-line argument.
pub fn data(name: &str) -> String {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data/intel"))
        .join(name)
        .display()
        .to_string()
}
