//! The unit of the fitted heights (issue 41, docs/decisions.md#raster-units-bands-and-no-data-issue-41):
//! `--max-error` is in metres unless `--error-unit` says otherwise, and is converted into the
//! unit the raster's heights are in (`--z-unit`, else the band's unit type, else a compound CRS's
//! vertical unit) before the fit; the report and the stage line state both.

use raster_io::units::{parse_length_unit, LengthUnit, ZUnit, ZUnitSource, KNOWN_UNITS, METRE};
use raster_io::Raster;

use super::Args;
use crate::config::Config;
use crate::error::CliError;
use crate::terrain_io::z_unit_of;

/// The units a fit works in.
pub(super) struct FitUnits {
    /// The heights' unit as read (`None`: nothing declares one; taken as metres).
    pub data: Option<ZUnit>,
    /// The unit `--max-error` is given in.
    pub error: LengthUnit,
}

impl FitUnits {
    /// Data units per unit of `--max-error`.
    fn factor(&self) -> f64 {
        self.error.metres / self.data.map_or(1.0, |z| z.unit.metres)
    }

    /// `--max-error` in the data's unit (a factor of 1 leaves it bit for bit).
    pub fn to_data(&self, e: f64) -> f64 {
        e * self.factor()
    }

    /// The name of the heights' unit for the report (`z unit of the input` when undeclared).
    pub fn data_name(&self) -> Option<&'static str> {
        self.data.map(|z| z.unit.name)
    }

    /// The tolerance as the progress lines print it: `0.01 km (10 m)`, or the bare number
    /// where nothing declares a unit and --max-error is in metres (as before).
    pub fn describe(&self, tolerance_text: String, given: Option<f64>) -> String {
        match (self.data, given) {
            (Some(z), Some(e)) if self.factor() != 1.0 => {
                format!("{tolerance_text} {} ({e} {})", z.unit.name, self.error.name)
            }
            (Some(z), _) => format!("{tolerance_text} {}", z.unit.name),
            _ => tolerance_text,
        }
    }
}

/// Resolves the units of the fit and says on stderr what the tolerance is in the data's unit.
pub(super) fn resolve(r: &Raster, name: &str, args: &Args, config: &Config) -> Result<FitUnits, CliError> {
    let error = match args.error_unit.as_deref() {
        None => METRE,
        Some(u) => parse_length_unit(u)
            .ok_or_else(|| CliError::usage(format!("--error-unit '{u}' is not a unit geofit knows ({KNOWN_UNITS})")))?,
    };
    let data = z_unit_of(r, name, args.z_unit.as_deref())?;
    let units = FitUnits { data, error };
    // stated where the numbers change: heights in another unit than --max-error's
    if let Some(z) = data.filter(|_| units.factor() != 1.0) {
        let from = match z.source {
            ZUnitSource::Given => "--z-unit",
            ZUnitSource::Band => "the band's unit type",
            ZUnitSource::VerticalCrs => "the CRS's vertical unit",
        };
        let tolerance = match args.max_error {
            Some(e) => format!(": --max-error {e} {} is {} {}", error.name, units.to_data(e), z.unit.name),
            None => String::new(),
        };
        config.notice(&format!("{name}: heights in {} ({from}){tolerance}", z.unit.name));
    } else if data.is_none() && error.metres != 1.0 {
        return Err(CliError::usage(format!(
            "--error-unit {}: {name} declares no unit for its heights, so --max-error cannot be converted; give --z-unit UNIT",
            error.name
        )));
    }
    Ok(units)
}
