//! Parameters from and to TOML: parsing a file or text into [`Params`] (with line and column on
//! syntax errors) and the commented TOML that `planet params` prints.

use std::path::Path;

use super::schema::{
    describe_toml, from_toml_value, line_column, spec_index, suggest_key, suggest_top_level,
    unknown_key,
};
use super::{BOUNDS, ParamError, Params, SCHEMA, SECTIONS};

/// The top-level TOML table that holds plugin parameters (`[plugins.<plugin>]`); [`Params`]
/// skips it, [`PluginParams`](crate::resources::plugin_params::PluginParams) reads it.
pub const PLUGINS_TABLE: &str = "plugins";

/// Parses TOML text into a table; syntax errors give their line and column.
pub(crate) fn parse_toml_table(text: &str) -> Result<toml::Table, ParamError> {
    toml::from_str(text).map_err(|e: toml::de::Error| {
        let (line, column) = match e.span() {
            Some(span) => {
                let (l, c) = line_column(text, span.start);
                (Some(l), Some(c))
            }
            None => (None, None),
        };
        ParamError::MalformedToml {
            line,
            column,
            message: e.to_string().trim_end().to_string(),
        }
    })
}

/// Reads a parameter file as text, once and at most
/// [`MAX_CONFIG_BYTES`](crate::resources::input::MAX_CONFIG_BYTES) of it, with errors naming the
/// path (missing, a folder, too large, unreadable). Pipes are read (`--config <(...)`); read the
/// text once and give it to both [`Params::from_toml_str`] and
/// [`PluginConfig::from_toml_str`](crate::resources::plugin_params::PluginConfig::from_toml_str).
pub fn read_param_file(path: &Path) -> Result<String, ParamError> {
    use crate::resources::input::{MAX_CONFIG_BYTES, TextFileError, read_text_capped};
    let owned = || path.to_path_buf();
    read_text_capped(path, MAX_CONFIG_BYTES).map_err(|e| match e {
        TextFileError::Missing => ParamError::FileNotFound { path: owned() },
        TextFileError::Folder => ParamError::IsDirectory { path: owned() },
        TextFileError::TooLarge { limit } => ParamError::FileTooLarge {
            path: owned(),
            limit,
        },
        TextFileError::NotUtf8 => ParamError::Unreadable {
            path: owned(),
            source: std::io::Error::new(std::io::ErrorKind::InvalidData, "not UTF-8 text"),
        },
        TextFileError::NotAFile(kind) => ParamError::Unreadable {
            path: owned(),
            source: std::io::Error::other(format!("it is {kind}")),
        },
        TextFileError::Io(source) => ParamError::Unreadable {
            path: owned(),
            source,
        },
    })
}

impl Params {
    /// Parses parameters from TOML text. Starts from the defaults; the text may give
    /// any subset of sections and keys. The result is fully validated.
    pub fn from_toml_str(text: &str) -> Result<Params, ParamError> {
        let table = parse_toml_table(text)?;
        let mut params = Params::default();
        for (section, value) in &table {
            if section == PLUGINS_TABLE {
                // Plugin parameters: read by `PluginParams` (src/io/plugin_params.rs).
                continue;
            }
            let is_section = SECTIONS.contains(&section.as_str());
            let entries = match value {
                toml::Value::Table(t) if is_section => t,
                toml::Value::Table(_) => {
                    return Err(ParamError::UnknownSection {
                        section: section.clone(),
                        suggestion: suggest_top_level(section),
                    });
                }
                other if is_section => {
                    return Err(ParamError::SectionNotTable {
                        section: section.clone(),
                        found: describe_toml(other),
                    });
                }
                _ => return Err(unknown_key(section)),
            };
            for (name, value) in entries {
                let key = format!("{section}.{name}");
                let Some(index) = spec_index(&key) else {
                    return Err(ParamError::UnknownKey {
                        key,
                        suggestion: suggest_key(section, name),
                    });
                };
                let Some(spec) = SCHEMA.get(index) else {
                    return Err(unknown_key(&key));
                };
                let v = from_toml_value(spec, value)?;
                params.set(&key, v)?;
            }
        }
        params.validate()?;
        Ok(params)
    }

    /// Reads and parses a TOML parameter file (see [`Params::from_toml_str`]).
    pub fn load(path: &Path) -> Result<Params, ParamError> {
        Params::from_toml_str(&read_param_file(path)?)
    }

    /// Prints every section and key as TOML, each key preceded by a comment
    /// `# doc [unit] (range min..max)` (the unit part is left out for dimensionless
    /// values). The output parses back with [`Params::from_toml_str`] to an equal
    /// `Params` (provided `self` is valid).
    pub fn to_commented_toml(&self) -> String {
        let mut out = String::new();
        out.push_str("# Parameters of the tectonic planet generator, in physical units.\n");
        out.push_str(
            "# Every section and key is optional: anything left out takes the default value.\n",
        );
        let mut current = "";
        for (spec, (lo, hi)) in SCHEMA.iter().zip(BOUNDS) {
            if spec.section != current {
                current = spec.section;
                out.push_str(&format!("\n[{current}]\n"));
            }
            let unit = if spec.unit.is_empty() {
                String::new()
            } else {
                format!(" [{}]", spec.unit)
            };
            out.push_str(&format!("# {}{} (range {}..{})\n", spec.doc, unit, lo, hi));
            let value = self.get_field(spec.key).unwrap_or(spec.default);
            out.push_str(&format!("{} = {}\n", spec.name, value));
        }
        out
    }
}
