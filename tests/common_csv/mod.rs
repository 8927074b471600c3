//! Output files as the experiment tests compare them: their lines, and `matches.csv` without
//! its wall-time column, the only column that varies from run to run.

use std::path::Path;

/// The lines of `path` (the test fails if it cannot be read).
pub fn lines(path: &Path) -> Vec<String> {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .map(str::to_string)
        .collect()
}

/// `rows` (header first) without the `ms` column.
pub fn without_times(rows: &[String]) -> Vec<String> {
    let ms = rows[0]
        .split(',')
        .position(|h| h == "ms")
        .expect("an ms column");
    rows.iter()
        .map(|r| {
            r.split(',')
                .enumerate()
                .filter(|(i, _)| *i != ms)
                .map(|(_, v)| v)
                .collect::<Vec<_>>()
                .join(",")
        })
        .collect()
}
