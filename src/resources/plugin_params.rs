//! Parameters declared by plugins: a registry resource ([`PluginParams`]) that plugins fill from
//! their `build` ([`PluginParamsAppExt::register_plugin_param`]), read from the `[plugins.<plugin>]`
//! tables of a TOML config ([`PluginConfig`]), checked like the core parameters (key, value,
//! range; unknown keys refused), printed by `planet params` and kept in saves (section
//! `core.plugin_params`).
//!
//! Every plugin parameter is described by a [`ParamSpec`] whose `key` is the full TOML path,
//! `plugins.<plugin>.<name>` (e.g. `plugins.hotspots.radius_km`), so the key in an error message
//! is the one to write in the config file.

use std::path::Path;

use bevy_app::App;
use bevy_ecs::prelude::*;

use crate::resources::params::{
    PLUGINS_TABLE, ParamError, ParamKind, ParamSpec, ParamValue, check_value, describe_toml,
    from_toml_value, levenshtein, parse_toml_table, read_param_file, suggest_threshold,
};
use crate::resources::save_section::{SaveSection, SectionError, SectionReader, SectionWriter};

/// One registered plugin parameter and its current value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PluginParam {
    /// Its description (key, unit, range, default, doc).
    pub spec: ParamSpec,
    /// Its current value (always of the spec's kind and within its range).
    pub value: ParamValue,
}

impl PluginParam {
    /// The smallest and largest allowed values, in the parameter's kind.
    pub fn bounds(&self) -> (ParamValue, ParamValue) {
        bounds_of(&self.spec)
    }
}

fn bounds_of(spec: &ParamSpec) -> (ParamValue, ParamValue) {
    match spec.kind {
        ParamKind::Float => (ParamValue::Float(spec.min), ParamValue::Float(spec.max)),
        ParamKind::Int => (
            ParamValue::Int(spec.min.max(0.0) as u64),
            ParamValue::Int(spec.max.max(0.0) as u64),
        ),
        ParamKind::Bool => (ParamValue::Bool(false), ParamValue::Bool(true)),
    }
}

/// Every parameter declared by a plugin, in registration order, with its current value (a
/// resource). The viewer lists them with [`Self::iter`] and changes them with [`Self::set`].
#[derive(Resource, Clone, Debug, Default, PartialEq)]
pub struct PluginParams {
    entries: Vec<PluginParam>,
    /// The first invalid declaration, reported by `Simulation::with_plugins`.
    invalid: Option<String>,
}

impl PluginParams {
    /// Declares a parameter at its default value. The key must be `plugins.<plugin>.<name>`, with
    /// `section` = `plugins.<plugin>` and `name` = `<name>`; the range must hold the default. A
    /// bad declaration is remembered and refused when the simulation is built; declaring a key
    /// twice keeps the first declaration.
    pub fn register(&mut self, spec: ParamSpec) {
        if self.entries.iter().any(|e| e.spec.key == spec.key) {
            return;
        }
        if let Err(e) = Self::check_spec(&spec) {
            self.invalid.get_or_insert(e);
            return;
        }
        self.entries.push(PluginParam {
            spec,
            value: spec.default,
        });
    }

    fn check_spec(spec: &ParamSpec) -> Result<(), String> {
        let well_formed = spec.section.strip_prefix("plugins.").is_some_and(|plugin| {
            !plugin.is_empty() && !plugin.contains('.') && !spec.name.contains('.')
        }) && spec.key == format!("{}.{}", spec.section, spec.name)
            && !spec.name.is_empty();
        if !well_formed {
            return Err(format!(
                "plugin parameter \"{}\" must have a key plugins.<plugin>.<name> made of its section \"{}\" and name \"{}\"",
                spec.key, spec.section, spec.name
            ));
        }
        let kind_ok = matches!(
            (spec.kind, spec.default),
            (ParamKind::Float, ParamValue::Float(_))
                | (ParamKind::Int, ParamValue::Int(_))
                | (ParamKind::Bool, ParamValue::Bool(_))
        );
        if !kind_ok || spec.min.partial_cmp(&spec.max).is_none_or(|o| o.is_gt()) {
            return Err(format!(
                "plugin parameter \"{}\" has a default of the wrong kind or an empty range",
                spec.key
            ));
        }
        check_value(spec, bounds_of(spec), spec.default)
            .map(|_| ())
            .map_err(|e| format!("default of plugin parameter \"{}\": {e}", spec.key))
    }

    /// The first invalid declaration, if any (a plugin bug; the simulation refuses to start).
    pub fn invalid_declaration(&self) -> Option<&str> {
        self.invalid.as_deref()
    }

    /// Every parameter with its current value, in registration order.
    pub fn iter(&self) -> impl Iterator<Item = &PluginParam> {
        self.entries.iter()
    }

    /// Number of registered parameters.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether no plugin registered a parameter.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The current value of `key` (`plugins.<plugin>.<name>`), or `None` if no plugin declared it.
    pub fn get(&self, key: &str) -> Option<ParamValue> {
        self.entries
            .iter()
            .find(|e| e.spec.key == key)
            .map(|e| e.value)
    }

    /// The value of a float parameter, or `fallback` if `key` is not a declared float.
    pub fn f64_or(&self, key: &str, fallback: f64) -> f64 {
        match self.get(key) {
            Some(ParamValue::Float(x)) => x,
            _ => fallback,
        }
    }

    /// The value of an integer parameter, or `fallback` if `key` is not a declared integer.
    pub fn u64_or(&self, key: &str, fallback: u64) -> u64 {
        match self.get(key) {
            Some(ParamValue::Int(n)) => n,
            _ => fallback,
        }
    }

    /// The value of a boolean parameter, or `fallback` if `key` is not a declared boolean.
    pub fn bool_or(&self, key: &str, fallback: bool) -> bool {
        match self.get(key) {
            Some(ParamValue::Bool(b)) => b,
            _ => fallback,
        }
    }

    /// Sets `key` after checking kind, finiteness and range (the same rules and messages as
    /// [`Params::set`](crate::resources::params::Params::set)); on error nothing changes.
    pub fn set(&mut self, key: &str, value: ParamValue) -> Result<(), ParamError> {
        let suggestion = self.suggest(key);
        let Some(entry) = self.entries.iter_mut().find(|e| e.spec.key == key) else {
            return Err(ParamError::UnknownKey {
                key: key.to_string(),
                suggestion,
            });
        };
        entry.value = check_value(&entry.spec, bounds_of(&entry.spec), value)?;
        Ok(())
    }

    /// Resets every parameter to its default.
    pub fn reset(&mut self) {
        for e in &mut self.entries {
            e.value = e.spec.default;
        }
    }

    /// The nearest declared key to an unknown one, if it is close.
    fn suggest(&self, key: &str) -> Option<String> {
        self.entries
            .iter()
            .map(|e| (levenshtein(key, e.spec.key), e.spec.key))
            .min_by_key(|(d, _)| *d)
            .filter(|(d, _)| *d <= suggest_threshold(key))
            .map(|(_, k)| k.to_string())
    }

    /// Applies the values of a config (every key checked first; on error nothing changes).
    pub fn apply(&mut self, config: &PluginConfig) -> Result<(), ParamError> {
        let mut next = self.clone();
        for (key, value) in &config.entries {
            let Some(entry) = next.entries.iter().find(|e| e.spec.key == *key) else {
                return Err(ParamError::UnknownKey {
                    key: key.clone(),
                    suggestion: self.suggest(key),
                });
            };
            let v = from_toml_value(&entry.spec, value)?;
            next.set(key, v)?;
        }
        *self = next;
        Ok(())
    }

    /// The parameters as commented TOML tables `[plugins.<plugin>]`, in the style of
    /// [`Params::to_commented_toml`](crate::resources::params::Params::to_commented_toml) (empty when no
    /// plugin declared any). Parses back with [`PluginConfig::from_toml_str`].
    pub fn to_commented_toml(&self) -> String {
        let mut out = String::new();
        let mut current = "";
        for e in &self.entries {
            if e.spec.section != current {
                current = e.spec.section;
                out.push_str(&format!("\n[{current}]\n"));
            }
            let unit = if e.spec.unit.is_empty() {
                String::new()
            } else {
                format!(" [{}]", e.spec.unit)
            };
            let (lo, hi) = e.bounds();
            out.push_str(&format!(
                "# {}{} (range {}..{})\n",
                e.spec.doc, unit, lo, hi
            ));
            out.push_str(&format!("{} = {}\n", e.spec.name, e.value));
        }
        out
    }
}

/// The plugin parameter values given by a TOML config: its `[plugins.<plugin>]` tables, not yet
/// checked (the plugins that declare them are known only once the simulation is built; apply
/// with [`PluginParams::apply`] or `Simulation::apply_plugin_config`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PluginConfig {
    entries: Vec<(String, toml::Value)>,
}

impl PluginConfig {
    /// Reads the `[plugins.<plugin>]` tables of TOML text (the other tables are left to
    /// [`Params`](crate::resources::params::Params)). A `plugins` value that is not a table of tables
    /// is refused.
    pub fn from_toml_str(text: &str) -> Result<Self, ParamError> {
        let table = parse_toml_table(text)?;
        let mut entries = Vec::new();
        let Some(plugins) = table.get(PLUGINS_TABLE) else {
            return Ok(Self { entries });
        };
        let toml::Value::Table(plugins) = plugins else {
            return Err(ParamError::SectionNotTable {
                section: PLUGINS_TABLE.into(),
                found: describe_toml(plugins),
            });
        };
        for (plugin, value) in plugins {
            let section = format!("{PLUGINS_TABLE}.{plugin}");
            let toml::Value::Table(keys) = value else {
                return Err(ParamError::SectionNotTable {
                    section,
                    found: describe_toml(value),
                });
            };
            for (name, v) in keys {
                entries.push((format!("{section}.{name}"), v.clone()));
            }
        }
        Ok(Self { entries })
    }

    /// Reads a TOML config file (errors name the path).
    pub fn load(path: &Path) -> Result<Self, ParamError> {
        Self::from_toml_str(&read_param_file(path)?)
    }

    /// Whether the config gives no plugin parameter.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }
}

/// Declares plugin parameters from a plugin's `build`.
pub trait PluginParamsAppExt {
    /// Adds `spec` to the [`PluginParams`] registry at its default value.
    fn register_plugin_param(&mut self, spec: ParamSpec) -> &mut Self;
}

impl PluginParamsAppExt for App {
    fn register_plugin_param(&mut self, spec: ParamSpec) -> &mut Self {
        self.init_resource::<PluginParams>();
        self.world_mut()
            .resource_mut::<PluginParams>()
            .register(spec);
        self
    }
}

/// The save section of plugin parameter values (`core.plugin_params`). A save made before it
/// existed loads with every plugin parameter at its default.
pub fn plugin_params_section() -> SaveSection {
    SaveSection {
        name: "core.plugin_params",
        version: 1,
        save: save_plugin_params,
        load: load_plugin_params,
        default: Some(|world| {
            if let Some(mut p) = world.get_resource_mut::<PluginParams>() {
                p.reset();
            }
            Ok(())
        }),
    }
}

fn save_plugin_params(world: &mut World, w: &mut SectionWriter) -> Result<(), SectionError> {
    let entries: Vec<PluginParam> = world
        .get_resource::<PluginParams>()
        .map(|p| p.entries.clone())
        .unwrap_or_default();
    w.u32(entries.len() as u32);
    for e in &entries {
        w.str(e.spec.key);
        match e.value {
            ParamValue::Float(x) => {
                w.u8(0);
                w.f64(x);
            }
            ParamValue::Int(n) => {
                w.u8(1);
                w.u64(n);
            }
            ParamValue::Bool(b) => {
                w.u8(2);
                w.u64(u64::from(b));
            }
        }
    }
    Ok(())
}

fn load_plugin_params(
    world: &mut World,
    r: &mut SectionReader,
    _v: u32,
) -> Result<(), SectionError> {
    let n = r.u32()?;
    let mut values = Vec::new();
    for _ in 0..n {
        if r.remaining() < 13 {
            return Err(format!("{n} values announced, the data ends early").into());
        }
        let key = r.str()?.to_string();
        let value = match r.u8()? {
            0 => ParamValue::Float(r.f64()?),
            1 => ParamValue::Int(r.u64()?),
            2 => match r.u64()? {
                0 => ParamValue::Bool(false),
                1 => ParamValue::Bool(true),
                b => return Err(format!("\"{key}\": boolean {b} is neither 0 nor 1").into()),
            },
            k => return Err(format!("\"{key}\": unknown value kind {k}").into()),
        };
        values.push((key, value));
    }
    r.finish()?;
    world.init_resource::<PluginParams>();
    let mut params = world.resource_mut::<PluginParams>();
    params.reset();
    for (key, value) in values {
        params.set(&key, value).map_err(|e| match e {
            ParamError::UnknownKey { .. } => format!(
                "the save sets plugin parameter \"{key}\", which no plugin of this simulation declares"
            ),
            e => e.to_string(),
        })?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const RADIUS: ParamSpec = ParamSpec {
        key: "plugins.demo.radius_km",
        section: "plugins.demo",
        name: "radius_km",
        kind: ParamKind::Float,
        unit: "km",
        doc: "Radius.",
        default: ParamValue::Float(100.0),
        min: 1.0,
        max: 1000.0,
    };
    const COUNT: ParamSpec = ParamSpec {
        key: "plugins.demo.count",
        section: "plugins.demo",
        name: "count",
        kind: ParamKind::Int,
        unit: "",
        doc: "How many.",
        default: ParamValue::Int(3),
        min: 0.0,
        max: 10.0,
    };

    fn registry() -> PluginParams {
        let mut p = PluginParams::default();
        p.register(RADIUS);
        p.register(COUNT);
        p
    }

    #[test]
    fn set_checks_kind_range_and_key() {
        let mut p = registry();
        p.set("plugins.demo.radius_km", ParamValue::Int(200))
            .unwrap();
        assert_eq!(p.f64_or("plugins.demo.radius_km", 0.0), 200.0);
        let e = p
            .set("plugins.demo.radius_km", ParamValue::Float(0.5))
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "parameter \"plugins.demo.radius_km\" = 0.5 is out of range: allowed 1.0..=1000.0"
        );
        let e = p
            .set("plugins.demo.count", ParamValue::Float(2.5))
            .unwrap_err();
        assert!(matches!(e, ParamError::NotIntegral { .. }), "{e:?}");
        let e = p
            .set("plugins.demo.radius", ParamValue::Float(2.0))
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "unknown parameter \"plugins.demo.radius\"; did you mean \"plugins.demo.radius_km\"?"
        );
        assert_eq!(p.u64_or("plugins.demo.count", 99), 3);
    }

    #[test]
    fn config_round_trips_and_refuses_bad_values() {
        let mut p = registry();
        p.set("plugins.demo.count", ParamValue::Int(7)).unwrap();
        let text = p.to_commented_toml();
        assert!(
            text.contains(
                "[plugins.demo]\n# Radius. [km] (range 1.0..1000.0)\nradius_km = 100.0\n"
            ),
            "{text}"
        );
        let mut q = registry();
        q.apply(&PluginConfig::from_toml_str(&text).unwrap())
            .unwrap();
        assert_eq!(q, p);
        // The core parameters ignore the plugin tables, and the plugin config the core ones.
        let both = format!("[planet]\nsamples = 2000\n{text}");
        assert_eq!(
            crate::resources::params::Params::from_toml_str(&both)
                .unwrap()
                .planet
                .samples,
            2000
        );
        let cfg = PluginConfig::from_toml_str("[plugins.demo]\ncount = 11\n").unwrap();
        let e = q.apply(&cfg).unwrap_err();
        assert_eq!(
            e.to_string(),
            "parameter \"plugins.demo.count\" = 11 is out of range: allowed 0..=10"
        );
        assert_eq!(q, p, "a refused config changes nothing");
        let cfg = PluginConfig::from_toml_str("[plugins.demo]\nradius_km = \"far\"\n").unwrap();
        assert!(
            q.apply(&cfg)
                .unwrap_err()
                .to_string()
                .contains("must be a number")
        );
        let cfg = PluginConfig::from_toml_str("[plugins.other]\nx = 1\n").unwrap();
        assert!(matches!(q.apply(&cfg), Err(ParamError::UnknownKey { .. })));
        assert!(matches!(
            PluginConfig::from_toml_str("plugins = 3\n"),
            Err(ParamError::SectionNotTable { .. })
        ));
        assert!(matches!(
            PluginConfig::from_toml_str("[plugins]\ndemo = 3\n"),
            Err(ParamError::SectionNotTable { .. })
        ));
    }

    #[test]
    fn bad_declarations_are_remembered() {
        let mut p = PluginParams::default();
        p.register(ParamSpec {
            key: "demo.radius_km",
            section: "demo",
            ..RADIUS
        });
        assert!(p.invalid_declaration().is_some());
        let mut p = PluginParams::default();
        p.register(ParamSpec {
            default: ParamValue::Float(5000.0),
            ..RADIUS
        });
        assert!(p.invalid_declaration().unwrap().contains("out of range"));
        assert!(registry().invalid_declaration().is_none());
    }
}
