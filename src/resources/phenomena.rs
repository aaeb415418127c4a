//! The registry of phenomena (one per plugin) with their run-time on/off switches. Every
//! phenomenon system runs under `run_if(phenomenon_enabled(name))`, so the CLI, the viewer or a
//! script can switch it off between steps without rebuilding the schedule.

use bevy_ecs::prelude::*;

use crate::plugins::TectonicSystems;

/// Description of one registered phenomenon.
#[derive(Clone, Debug, PartialEq)]
pub struct PhenomenonInfo {
    /// Short unique name used on the command line (`--disable erosion`).
    pub name: &'static str,
    /// The system set its systems live in.
    pub set: TectonicSystems,
    /// One line for listings.
    pub description: &'static str,
    /// Whether its systems run.
    pub enabled: bool,
    /// Whether it is on in a new simulation (what `planet plugins` shows as the default).
    pub default_enabled: bool,
}

/// All registered phenomena in registration order (a resource).
#[derive(Resource, Clone, Debug, Default, PartialEq)]
pub struct Phenomena {
    entries: Vec<PhenomenonInfo>,
}

impl Phenomena {
    /// Adds a phenomenon (enabled). Registering a name twice keeps the first entry.
    pub fn register(
        &mut self,
        name: &'static str,
        set: TectonicSystems,
        description: &'static str,
    ) {
        self.register_with_default(name, set, description, true);
    }
    /// Adds a phenomenon that starts on (`enabled_by_default`) or off. Registering a name twice
    /// keeps the first entry.
    pub fn register_with_default(
        &mut self,
        name: &'static str,
        set: TectonicSystems,
        description: &'static str,
        enabled_by_default: bool,
    ) {
        if !self.entries.iter().any(|e| e.name == name) {
            self.entries.push(PhenomenonInfo {
                name,
                set,
                description,
                enabled: enabled_by_default,
                default_enabled: enabled_by_default,
            });
        }
    }
    /// Whether `name` is registered and enabled.
    pub fn is_enabled(&self, name: &str) -> bool {
        self.entries.iter().any(|e| e.name == name && e.enabled)
    }
    /// Switches `name` on or off; `Err` lists the registered names when it is unknown.
    pub fn set_enabled(&mut self, name: &str, enabled: bool) -> Result<(), String> {
        match self.entries.iter_mut().find(|e| e.name == name) {
            Some(e) => {
                e.enabled = enabled;
                Ok(())
            }
            None => Err(format!(
                "unknown phenomenon \"{name}\"; registered: {}",
                self.entries
                    .iter()
                    .map(|e| e.name)
                    .collect::<Vec<_>>()
                    .join(", ")
            )),
        }
    }
    /// Every registered phenomenon.
    pub fn iter(&self) -> impl Iterator<Item = &PhenomenonInfo> {
        self.entries.iter()
    }
}

/// Run condition: true while the named phenomenon is enabled.
pub fn phenomenon_enabled(
    name: &'static str,
) -> impl FnMut(Option<Res<Phenomena>>) -> bool + Clone {
    move |p: Option<Res<Phenomena>>| p.is_some_and(|p| p.is_enabled(name))
}
