//! Helpers shared by the integration tests.

/// Reads a two-column DaISy record `shared/data/real/<folder>/<file>` in place (whitespace
/// separated u, y) and checks its length.
pub fn daisy(folder: &str, file: &str, rows: usize) -> Vec<(f64, f64)> {
    let path = format!(
        "{}/../../../shared/data/real/{folder}/{file}",
        env!("CARGO_MANIFEST_DIR")
    );
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    let data: Vec<(f64, f64)> = text
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let mut it = l.split_whitespace().map(|v| v.parse::<f64>().unwrap());
            (it.next().unwrap(), it.next().unwrap())
        })
        .collect();
    assert_eq!(data.len(), rows, "{path}");
    data
}
