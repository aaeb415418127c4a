//! The parameter schema: values, kinds, the declaration of each parameter ([`ParamSpec`]), the
//! errors, and the checks and suggestions shared by the core and plugin parameters.

use std::fmt;
use std::path::PathBuf;

use super::{SCHEMA, SECTIONS};
use crate::resources::input::{clip, clip_lines};

/// A parameter value of one of the supported kinds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ParamValue {
    /// A real number (always finite once accepted).
    Float(f64),
    /// A non-negative integer.
    Int(u64),
    /// A boolean flag.
    Bool(bool),
}

impl fmt::Display for ParamValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ParamValue::Float(x) => f.write_str(&format_float(*x)),
            ParamValue::Int(n) => write!(f, "{n}"),
            ParamValue::Bool(b) => write!(f, "{b}"),
        }
    }
}

/// The kind (type) of a parameter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParamKind {
    /// Stored as `f64`.
    Float,
    /// Stored as `u64`.
    Int,
    /// Stored as `bool`.
    Bool,
}

impl ParamKind {
    /// What a value of this kind must look like, for error messages.
    fn expectation(self) -> &'static str {
        match self {
            ParamKind::Float => "a number",
            ParamKind::Int => "a non-negative integer",
            ParamKind::Bool => "true or false",
        }
    }
}

/// Description of one parameter, as declared in the parameter table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamSpec {
    /// Full dotted key, e.g. `"ocean.ridge_elevation_km"`.
    pub key: &'static str,
    /// Section (TOML table) name, e.g. `"ocean"`.
    pub section: &'static str,
    /// Key name within the section, e.g. `"ridge_elevation_km"`.
    pub name: &'static str,
    /// Value kind.
    pub kind: ParamKind,
    /// Physical unit (may be empty for dimensionless values).
    pub unit: &'static str,
    /// One-line description.
    pub doc: &'static str,
    /// Default value.
    pub default: ParamValue,
    /// Smallest allowed value (inclusive), as `f64`. Integer bounds are
    /// checked exactly against their declared integer values.
    pub min: f64,
    /// Largest allowed value (inclusive), as `f64`. Integer bounds are
    /// checked exactly against their declared integer values.
    pub max: f64,
}

/// Everything that can go wrong while setting, loading or validating parameters.
/// The `Display` text is meant to be shown to users as is.
#[derive(Debug, thiserror::Error)]
pub enum ParamError {
    /// The parameter file does not exist.
    #[error("parameter file \"{}\" does not exist", path.display())]
    FileNotFound {
        /// The path that was given.
        path: PathBuf,
    },
    /// The parameter path names a directory.
    #[error("parameter file \"{}\" is a directory, not a file", path.display())]
    IsDirectory {
        /// The path that was given.
        path: PathBuf,
    },
    /// The parameter file is larger than [`MAX_CONFIG_BYTES`](crate::resources::input::MAX_CONFIG_BYTES).
    #[error(
        "parameter file \"{}\" is larger than {} (a parameter file is a few KB; is it the right file?)",
        path.display(), crate::resources::input::bytes_in_words(*limit)
    )]
    FileTooLarge {
        /// The path that was given.
        path: PathBuf,
        /// The cap, bytes.
        limit: u64,
    },
    /// The parameter file exists but could not be read (permissions, not UTF-8, ...).
    #[error("cannot read parameter file \"{}\": {source}", path.display())]
    Unreadable {
        /// The path that was given.
        path: PathBuf,
        /// The underlying I/O error.
        source: std::io::Error,
    },
    /// The text is not valid TOML.
    #[error("malformed TOML: {}", clip_lines(message, 12))]
    MalformedToml {
        /// 1-based line of the error, when known.
        line: Option<usize>,
        /// 1-based column (in characters) of the error, when known.
        column: Option<usize>,
        /// The TOML parser's full message (includes line, column and an excerpt).
        message: String,
    },
    /// A top-level table that is not a parameter section.
    #[error(
        "unknown parameter section [{}]{}",
        clip(section),
        fmt_suggestion(suggestion)
    )]
    UnknownSection {
        /// The section name as written.
        section: String,
        /// The nearest valid section or full key, if any is close.
        suggestion: Option<String>,
    },
    /// A section name was used with a non-table value (e.g. `ocean = 3`).
    #[error(
        "\"{section}\" is a parameter section and must be a table ([{section}]), got {}",
        clip(found)
    )]
    SectionNotTable {
        /// The section name.
        section: String,
        /// Description of what was found instead.
        found: String,
    },
    /// A key that is not a parameter.
    #[error("unknown parameter \"{}\"{}", clip(key), fmt_suggestion(suggestion))]
    UnknownKey {
        /// The full dotted key as written.
        key: String,
        /// The nearest valid full key, if any is close.
        suggestion: Option<String>,
    },
    /// The value has the wrong type for the parameter.
    #[error("parameter \"{}\" must be {}, got {}", clip(key), expected.expectation(), clip(found))]
    WrongType {
        /// The full dotted key.
        key: String,
        /// The kind the parameter has.
        expected: ParamKind,
        /// Description of the value that was given.
        found: String,
    },
    /// A non-integral number was given for an integer parameter.
    #[error("parameter \"{}\" must be an integer, got {}", clip(key), format_float(*value))]
    NotIntegral {
        /// The full dotted key.
        key: String,
        /// The value given.
        value: f64,
    },
    /// A negative number was given for an integer parameter.
    #[error(
        "parameter \"{}\" must be a non-negative integer, got {}",
        clip(key),
        clip(value)
    )]
    Negative {
        /// The full dotted key.
        key: String,
        /// The value given, as written.
        value: String,
    },
    /// NaN or an infinity was given.
    #[error("parameter \"{}\" = {} is not a finite number", clip(key), format_float(*value))]
    NonFinite {
        /// The full dotted key.
        key: String,
        /// The value given.
        value: f64,
    },
    /// The value lies outside the parameter's allowed range.
    #[error(
        "parameter \"{}\" = {value} is out of range: allowed {min}..={max}",
        clip(key)
    )]
    OutOfRange {
        /// The full dotted key.
        key: String,
        /// The value given.
        value: ParamValue,
        /// Smallest allowed value.
        min: ParamValue,
        /// Largest allowed value.
        max: ParamValue,
    },
    /// More plates than the sample count can support.
    #[error(
        "init.plates = {plates} is too many for planet.samples = {samples}: every plate needs at least 20 samples, so at most {max_plates} plates are allowed (lower init.plates or raise planet.samples)"
    )]
    TooManyPlates {
        /// `init.plates`.
        plates: u64,
        /// `planet.samples`.
        samples: u64,
        /// `planet.samples / 20`.
        max_plates: u64,
    },
    /// Oceanic reference elevations are not ordered.
    #[error(
        "oceanic elevations must satisfy ocean.trench_elevation_km < ocean.abyssal_elevation_km < ocean.ridge_elevation_km < 0, got {} < {} < {} < 0",
        format_float(*trench), format_float(*abyssal), format_float(*ridge)
    )]
    OceanElevationOrder {
        /// `ocean.trench_elevation_km`.
        trench: f64,
        /// `ocean.abyssal_elevation_km`.
        abyssal: f64,
        /// `ocean.ridge_elevation_km`.
        ridge: f64,
    },
    /// Resampling interval bounds are inverted.
    #[error(
        "resample.min_interval_steps = {min} must not exceed resample.max_interval_steps = {max}"
    )]
    ResampleInterval {
        /// `resample.min_interval_steps`.
        min: u64,
        /// `resample.max_interval_steps`.
        max: u64,
    },
    /// Two parameters that must be ordered are not.
    #[error(
        "{lower_key} = {} must be {} {upper_key} = {}: {why}",
        format_float(*lower), if *strict { "below" } else { "at most" }, format_float(*upper)
    )]
    OutOfOrder {
        /// The key that must be the smaller.
        lower_key: &'static str,
        /// Its value.
        lower: f64,
        /// The key that must be the larger.
        upper_key: &'static str,
        /// Its value.
        upper: f64,
        /// Whether equal values are refused too.
        strict: bool,
        /// What the order means.
        why: &'static str,
    },
}

fn fmt_suggestion(s: &Option<String>) -> String {
    match s {
        Some(s) => format!("; did you mean \"{s}\"?"),
        None => String::new(),
    }
}

/// Formats a float so that it parses back (in Rust and TOML) to the same value:
/// shortest round-trip digits, always with a `.` or exponent; `nan`/`inf` as TOML spells them.
pub(crate) fn format_float(x: f64) -> String {
    if x.is_nan() {
        "nan".to_string()
    } else if x.is_infinite() {
        if x > 0.0 {
            "inf".to_string()
        } else {
            "-inf".to_string()
        }
    } else {
        // `{:?}` gives shortest round-trip digits: 6370.0, 1.3e-5, 1e16.
        format!("{x:?}")
    }
}

/// Keys longer than this get no suggestion (keeps the edit-distance work bounded).
const MAX_SUGGEST_LEN: usize = 256;

/// Levenshtein edit distance between two strings, counted in `char`s.
pub(crate) fn levenshtein(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    let mut cur: Vec<usize> = vec![0; b.len() + 1];
    for (i, ca) in a.chars().enumerate() {
        cur[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let sub = prev[j] + usize::from(ca != *cb);
            cur[j + 1] = sub.min(prev[j + 1] + 1).min(cur[j] + 1);
        }
        std::mem::swap(&mut prev, &mut cur);
    }
    prev[b.len()]
}

/// Largest edit distance at which a suggestion is offered for `s`.
pub(crate) fn suggest_threshold(s: &str) -> usize {
    2.max(s.chars().count() / 4)
}

/// Nearest valid full key for an unknown `section.name`: either a close full key,
/// or the same (or a close) name in another section.
pub(crate) fn suggest_key(section: &str, name: &str) -> Option<String> {
    if section.len() + name.len() > MAX_SUGGEST_LEN {
        return None;
    }
    let full = format!("{section}.{name}");
    let mut best: Option<(usize, &'static str)> = None;
    for spec in SCHEMA {
        let by_full = levenshtein(&full, spec.key);
        // A right (or nearly right) name in the wrong section costs one edit.
        let by_name = levenshtein(name, spec.name) + usize::from(section != spec.section);
        let d = by_full.min(by_name);
        if best.is_none_or(|(bd, _)| d < bd) {
            best = Some((d, spec.key));
        }
    }
    match best {
        Some((d, key)) if d <= suggest_threshold(&full) => Some(key.to_string()),
        _ => None,
    }
}

/// Suggestion for an unknown top-level name: a close section name, or the full key
/// of a parameter with that (or a close) name.
pub(crate) fn suggest_top_level(name: &str) -> Option<String> {
    if name.len() > MAX_SUGGEST_LEN {
        return None;
    }
    let threshold = suggest_threshold(name);
    let mut best: Option<(usize, String)> = None;
    for sec in SECTIONS {
        let d = levenshtein(name, sec);
        if best.as_ref().is_none_or(|(bd, _)| d < *bd) {
            best = Some((d, (*sec).to_string()));
        }
    }
    for spec in SCHEMA {
        // Missing section: one edit, plus any typo in the name.
        let d = levenshtein(name, spec.name) + 1;
        if best.as_ref().is_none_or(|(bd, _)| d < *bd) {
            best = Some((d, spec.key.to_string()));
        }
    }
    match best {
        Some((d, s)) if d <= threshold => Some(s),
        _ => None,
    }
}

/// Short description of a TOML value for error messages.
pub(crate) fn describe_toml(v: &toml::Value) -> String {
    match v {
        toml::Value::String(s) => {
            let shown: String = s.chars().take(40).collect();
            let ellipsis = if s.chars().count() > 40 { "..." } else { "" };
            format!("string {:?}", format!("{shown}{ellipsis}"))
        }
        toml::Value::Integer(i) => format!("integer {i}"),
        toml::Value::Float(x) => format!("float {}", format_float(*x)),
        toml::Value::Boolean(b) => format!("boolean {b}"),
        toml::Value::Datetime(d) => format!("datetime {d}"),
        toml::Value::Array(_) => "an array".to_string(),
        toml::Value::Table(_) => "a table".to_string(),
    }
}

/// Short description of a `ParamValue` for error messages.
pub(crate) fn describe_value(v: ParamValue) -> String {
    match v {
        ParamValue::Float(x) => format!("float {}", format_float(x)),
        ParamValue::Int(n) => format!("integer {n}"),
        ParamValue::Bool(b) => format!("boolean {b}"),
    }
}

/// Index of a key in the schema.
pub(crate) fn spec_index(key: &str) -> Option<usize> {
    SCHEMA.iter().position(|s| s.key == key)
}

/// Error for a key that is not in the schema.
pub(crate) fn unknown_key(key: &str) -> ParamError {
    let suggestion = match key.split_once('.') {
        Some((section, name)) => suggest_key(section, name),
        None => suggest_top_level(key),
    };
    ParamError::UnknownKey {
        key: key.to_string(),
        suggestion,
    }
}

/// Converts `value` to the kind of `spec` and checks finiteness and range.
pub(crate) fn check_value(
    spec: &ParamSpec,
    bounds: (ParamValue, ParamValue),
    value: ParamValue,
) -> Result<ParamValue, ParamError> {
    let key = || spec.key.to_string();
    let wrong = |v: ParamValue| ParamError::WrongType {
        key: key(),
        expected: spec.kind,
        found: describe_value(v),
    };
    let converted = match (spec.kind, value) {
        (ParamKind::Float, ParamValue::Float(x)) => ParamValue::Float(x),
        (ParamKind::Float, ParamValue::Int(n)) => ParamValue::Float(n as f64),
        (ParamKind::Int, ParamValue::Int(n)) => ParamValue::Int(n),
        (ParamKind::Int, ParamValue::Float(x)) => {
            if !x.is_finite() {
                return Err(ParamError::NonFinite {
                    key: key(),
                    value: x,
                });
            }
            if x.fract() != 0.0 {
                return Err(ParamError::NotIntegral {
                    key: key(),
                    value: x,
                });
            }
            if x < 0.0 {
                return Err(ParamError::Negative {
                    key: key(),
                    value: format_float(x),
                });
            }
            // 2^64 and above cannot be represented; they are out of any range anyway.
            if x >= 18_446_744_073_709_551_616.0 {
                return Err(ParamError::OutOfRange {
                    key: key(),
                    value: ParamValue::Float(x),
                    min: bounds.0,
                    max: bounds.1,
                });
            }
            ParamValue::Int(x as u64)
        }
        (ParamKind::Bool, ParamValue::Bool(b)) => ParamValue::Bool(b),
        (_, v) => return Err(wrong(v)),
    };
    let in_range = match (converted, bounds) {
        (ParamValue::Float(x), (ParamValue::Float(lo), ParamValue::Float(hi))) => {
            if !x.is_finite() {
                return Err(ParamError::NonFinite {
                    key: key(),
                    value: x,
                });
            }
            lo <= x && x <= hi
        }
        (ParamValue::Int(n), (ParamValue::Int(lo), ParamValue::Int(hi))) => lo <= n && n <= hi,
        (ParamValue::Bool(_), _) => true,
        _ => false,
    };
    if in_range {
        Ok(converted)
    } else {
        Err(ParamError::OutOfRange {
            key: key(),
            value: converted,
            min: bounds.0,
            max: bounds.1,
        })
    }
}

/// Converts a TOML value into a `ParamValue` for `spec` (type check only).
pub(crate) fn from_toml_value(spec: &ParamSpec, v: &toml::Value) -> Result<ParamValue, ParamError> {
    match (spec.kind, v) {
        (ParamKind::Float, toml::Value::Integer(i)) => Ok(ParamValue::Float(*i as f64)),
        (ParamKind::Int, toml::Value::Integer(i)) => u64::try_from(*i)
            .map(ParamValue::Int)
            .map_err(|_| ParamError::Negative {
                key: spec.key.to_string(),
                value: i.to_string(),
            }),
        (ParamKind::Float | ParamKind::Int, toml::Value::Float(x)) => Ok(ParamValue::Float(*x)),
        (ParamKind::Bool, toml::Value::Boolean(b)) => Ok(ParamValue::Bool(*b)),
        (kind, other) => Err(ParamError::WrongType {
            key: spec.key.to_string(),
            expected: kind,
            found: describe_toml(other),
        }),
    }
}

/// 1-based line and column (in chars) of a byte offset in `text`.
pub(crate) fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let mut line = 1;
    let mut column = 1;
    for (i, c) in text.char_indices() {
        if i >= offset {
            break;
        }
        if c == '\n' {
            line += 1;
            column = 1;
        } else {
            column += 1;
        }
    }
    (line, column)
}
