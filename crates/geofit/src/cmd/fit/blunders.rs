//! The blunders `geofit fit` found, told: all of them to `--outliers-csv`, the first few by
//! position on stderr with the prediction the screen compared them with.

use tspline_raster::screening::Screening;

use crate::config::Output;
use crate::error::CliError;

/// Blunders listed by position on stderr (all of them go to `--outliers-csv`).
const LISTED_OUTLIERS: usize = 5;

pub(super) fn report_blunders(s: &Screening, name: &str, k: f64, csv: Option<&str>) -> Result<(), CliError> {
    let reject = s.rejected;
    if let Some(path) = csv {
        Output::from_arg(Some(path)).write_with(|w| {
            let mut text = String::from("row,col,x,y,value,predicted,deviation,rejected\n");
            for (b, n) in s.found.iter().zip(&s.nearest) {
                let p = s.position(b.index);
                text.push_str(&format!(
                    "{},{},{},{},{},{n},{},{reject}\n",
                    p.row,
                    p.col,
                    p.x,
                    p.y,
                    b.value,
                    (b.value - n).abs()
                ));
            }
            w.write_all(text.as_bytes()).map_err(CliError::io_out)
        })?;
    }
    if s.found.is_empty() {
        return Ok(());
    }
    let list: Vec<String> = s
        .found
        .iter()
        .zip(&s.nearest)
        .take(LISTED_OUTLIERS)
        .map(|(b, n)| {
            let p = s.position(b.index);
            format!(
                "row {}, col {} (x {}, y {}): {} where the nearest local prediction is {n:.6}",
                p.row, p.col, p.x, p.y, b.value
            )
        })
        .collect();
    let more = if s.found.len() > LISTED_OUTLIERS {
        format!("; {} more", s.found.len() - LISTED_OUTLIERS)
    } else {
        String::new()
    };
    let what = if reject {
        "excluded from the fit and the data mask (--reject-outliers)"
    } else {
        "fitted as data; --reject-outliers K excludes them"
    };
    crate::say!(
        "geofit: {name}: {} blunder(s) (isolated cells more than {k} × the tolerance off their neighbourhood: blunders or single-cell features), {what}: {}{more}",
        s.found.len(),
        list.join("; ")
    );
    Ok(())
}
