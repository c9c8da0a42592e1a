//! Reading time-series and table CSV files back (probes.csv, energy.csv, reference
//! data) for the studies, sweeps and wave analysis. The writer is
//! `sph_core::series::SeriesWriter`.

use crate::StudyError;
use std::path::Path;

/// A CSV file as (header, rows of numbers), skipping `#` comment lines (the reference
/// data's source lines); a cell that is not a number reads NaN.
pub fn read_table(path: &Path) -> Result<(Vec<String>, Vec<Vec<f64>>), StudyError> {
    let at = |e: &dyn std::fmt::Display| StudyError::file(path, e);
    let mut reader = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .flexible(true)
        .trim(csv::Trim::All)
        .from_path(path)
        .map_err(|e| at(&e))?;
    let header = reader
        .headers()
        .map_err(|e| at(&e))?
        .iter()
        .map(str::to_string)
        .collect();
    let mut rows = Vec::new();
    for row in reader.records() {
        let row = row.map_err(|e| at(&e))?;
        rows.push(row.iter().map(|v| v.parse().unwrap_or(f64::NAN)).collect());
    }
    Ok((header, rows))
}

/// The header column `pattern` selects: a name, or `prefix.*` for the first column
/// starting with `prefix.` (e.g. `P1.*` whichever extraction method a run wrote).
pub fn find_column(header: &[String], pattern: &str) -> Option<usize> {
    match pattern.strip_suffix('*') {
        Some(prefix) => header.iter().position(|h| h.starts_with(prefix)),
        None => header.iter().position(|h| h == pattern),
    }
}

/// Column `expr` of a time-series CSV against its first column (time), rows with a
/// non-finite value left out. `expr` is a column ([`find_column`]) or a sum of columns
/// written `a+b` (e.g. `kinetic+potential` of energy.csv).
pub fn read_series(path: &Path, expr: &str) -> Result<Vec<(f64, f64)>, StudyError> {
    let (header, rows) = read_table(path)?;
    let columns = expr
        .split('+')
        .map(|name| {
            find_column(&header, name.trim()).ok_or_else(|| StudyError::NoColumn {
                path: path.to_path_buf(),
                column: name.trim().to_string(),
                columns: header.clone(),
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(rows
        .iter()
        .filter_map(|r| {
            let t = *r.first()?;
            let v: f64 = columns
                .iter()
                .map(|&k| r.get(k).copied().unwrap_or(f64::NAN))
                .sum();
            (t.is_finite() && v.is_finite()).then_some((t, v))
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_columns_sums_and_prefix_patterns_skipping_comments() {
        let dir = std::env::temp_dir().join(format!("sph-series-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("s.csv");
        std::fs::write(
            &path,
            "# source line\ntime,P1.nearest,a,b\n0,1,2,3\n1,4,5,x\n",
        )
        .unwrap();
        assert_eq!(
            read_series(&path, "P1.*").unwrap(),
            vec![(0.0, 1.0), (1.0, 4.0)]
        );
        assert_eq!(read_series(&path, "a + b").unwrap(), vec![(0.0, 5.0)]);
        let e = read_series(&path, "c").unwrap_err();
        assert!(
            matches!(&e, StudyError::NoColumn { column, columns, .. }
                if column == "c" && columns.len() == 4),
            "{e}"
        );
        assert!(e.to_string().contains("no column `c`"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
