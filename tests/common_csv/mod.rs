//! `matches.csv` without its wall-time column, shared by the experiment tests: the only column
//! that varies from run to run.

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
