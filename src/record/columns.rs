//! Columns a user's CSV files name otherwise than the data contract: a
//! logger or a spreadsheet writes `Time [s]`, `U_A` or `n_rpm`, and the
//! command line maps each to the contract's name (`--column
//! time_s="Time [s]"`) instead of the user rewriting every file. The map
//! renames header cells before the readers look for their columns, so
//! every reader (DC, slip sweep, the standard tests) and every check after
//! them sees the contract's names; a file without a mapped header is read
//! as it is (an induction machine's record mixes files of different
//! columns).

use std::fmt;

use super::csv::{
    COL_CURRENT, COL_CURRENT_MA, COL_SPEED, COL_SPEED_RPM, COL_TIME, COL_TIME_MS, COL_VOLTAGE,
};
use super::csv_im::{
    COL_FREQUENCY, COL_INPUT_POWER, COL_LINE_CURRENT, COL_LINE_VOLTAGE, COL_SLIP, COL_TORQUE,
};
use super::csv_im_tests::{COL_DC_CURRENT, COL_DC_VOLTAGE, COL_WINDING_TEMPERATURE};

/// Every column name a CSV reader looks for (each kind's, each unit's).
pub const CONTRACT_COLUMNS: [&str; 16] = [
    COL_TIME,
    COL_TIME_MS,
    COL_VOLTAGE,
    COL_CURRENT,
    COL_CURRENT_MA,
    COL_SPEED,
    COL_SPEED_RPM,
    COL_SLIP,
    COL_LINE_VOLTAGE,
    COL_LINE_CURRENT,
    COL_INPUT_POWER,
    COL_TORQUE,
    COL_FREQUENCY,
    COL_DC_VOLTAGE,
    COL_DC_CURRENT,
    COL_WINDING_TEMPERATURE,
];

/// Contract column ← the header cell that holds it in the user's files.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ColumnMap {
    pairs: Vec<(&'static str, String)>,
}

/// A mapping the map cannot take.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ColumnMapError {
    /// Not `NAME=HEADER`.
    #[error("{0:?}: expected CONTRACT_NAME=HEADER, e.g. time_s=\"Time [s]\"")]
    Form(String),
    /// The contract has no such column.
    #[error("{name:?} is not a column motorbench reads; the names are: {}", CONTRACT_COLUMNS.join(", "))]
    Unknown {
        /// The name given.
        name: String,
    },
    /// One contract column given twice, or one header given to two.
    #[error("{0} is mapped twice")]
    Twice(String),
}

impl ColumnMap {
    /// Map from `NAME=HEADER` pairs, as the command line gives them.
    pub fn parse<S: AsRef<str>>(pairs: &[S]) -> Result<ColumnMap, ColumnMapError> {
        pairs.iter().try_fold(ColumnMap::default(), |map, pair| {
            let pair = pair.as_ref();
            let (name, header) = pair
                .split_once('=')
                .filter(|(n, h)| !n.trim().is_empty() && !h.trim().is_empty())
                .ok_or_else(|| ColumnMapError::Form(pair.to_string()))?;
            map.with(name.trim(), header.trim())
        })
    }

    /// This map with `header` read as the contract's column `name`.
    pub fn with(mut self, name: &str, header: &str) -> Result<ColumnMap, ColumnMapError> {
        let name = CONTRACT_COLUMNS
            .into_iter()
            .find(|c| *c == name)
            .ok_or_else(|| ColumnMapError::Unknown {
                name: name.to_string(),
            })?;
        if self.pairs.iter().any(|(n, _)| *n == name) {
            return Err(ColumnMapError::Twice(name.to_string()));
        }
        if self.pairs.iter().any(|(_, h)| h == header) {
            return Err(ColumnMapError::Twice(format!("header {header:?}")));
        }
        self.pairs.push((name, header.to_string()));
        Ok(self)
    }

    /// Whether nothing is mapped.
    pub fn is_empty(&self) -> bool {
        self.pairs.is_empty()
    }

    /// `names` (a header row, quotes removed) with every mapped header
    /// cell replaced by its contract name.
    pub(super) fn rename(&self, names: &mut [&str]) {
        for cell in names.iter_mut() {
            if let Some((name, _)) = self.pairs.iter().find(|(_, h)| h == cell.trim()) {
                *cell = name;
            }
        }
    }
}

impl fmt::Display for ColumnMap {
    /// The map as the command line gives it, `--column` by `--column`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let pairs: Vec<String> = self
            .pairs
            .iter()
            .map(|(n, h)| format!("--column {n}={h:?}"))
            .collect();
        f.write_str(&pairs.join(" "))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mapped_headers_take_the_contract_names_and_the_rest_stay() {
        let map = ColumnMap::parse(&["time_s=Time [s]", "speed_rpm = n (rpm) "]).unwrap();
        let mut names = vec!["Time [s]", "U", " n (rpm)", "armature_current_A"];
        map.rename(&mut names);
        assert_eq!(names, ["time_s", "U", "speed_rpm", "armature_current_A"]);
        assert_eq!(
            map.to_string(),
            "--column time_s=\"Time [s]\" --column speed_rpm=\"n (rpm)\""
        );
    }

    #[test]
    fn a_bad_mapping_says_what_is_wrong() {
        let form = ColumnMap::parse(&["time_s"]).unwrap_err();
        assert_eq!(form, ColumnMapError::Form("time_s".into()));
        assert!(form.to_string().contains("CONTRACT_NAME=HEADER"));
        let unknown = ColumnMap::parse(&["speed=n"]).unwrap_err();
        assert!(matches!(unknown, ColumnMapError::Unknown { .. }));
        assert!(unknown.to_string().contains("speed_rad_s"), "{unknown}");
        assert_eq!(
            ColumnMap::parse(&["time_s=t", "time_s=T"]).unwrap_err(),
            ColumnMapError::Twice("time_s".into())
        );
        assert!(matches!(
            ColumnMap::parse(&["time_s=t", "time_ms=t"]).unwrap_err(),
            ColumnMapError::Twice(_)
        ));
        assert!(ColumnMap::parse(&["=t"]).is_err());
        assert!(ColumnMap::parse::<&str>(&[]).unwrap().is_empty());
    }
}
