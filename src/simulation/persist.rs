//! A simulation to and from save sections: [`Simulation::to_sections`] runs every registered
//! section writer; [`Simulation::from_sections`] rebuilds the world from the parameters and mesh
//! recipe, checks the sections against the registry and runs every reader. The file container
//! (header, compression, checksum, atomic writes) is `io::save`.

use bevy_app::PluginGroup;

use super::Simulation;
use super::core_sections::{MeshRecipe, parse_params, read_recipe, recipe_of};
use crate::resources::{
    LoadErrorKind, RawSection, SaveError, SaveRegistry, SaveSection, SectionReader, SectionWriter,
};
use crate::systems::init;

impl Simulation {
    /// Every registered section of this simulation's state, in registration order, encoded
    /// (uncompressed).
    pub fn to_sections(&mut self) -> Result<Vec<RawSection>, SaveError> {
        let world = self.world_mut();
        let sections: Vec<SaveSection> = world
            .get_resource::<SaveRegistry>()
            .map(|r| r.sections().to_vec())
            .unwrap_or_default();
        let mut raw = Vec::with_capacity(sections.len());
        for s in &sections {
            let mut w = SectionWriter::default();
            (s.save)(world, &mut w).map_err(|e| SaveError::Encode {
                section: s.name,
                message: e.to_string(),
            })?;
            raw.push(RawSection {
                name: s.name.to_string(),
                version: s.version,
                data: w.into_bytes(),
            });
        }
        Ok(raw)
    }

    /// Rebuilds a simulation from decoded save sections with the given plugin group (it must
    /// be the one the save was made with). Refuses sections no plugin reads, missing sections
    /// without a default, newer section versions, and a mesh that differs from the saved one.
    pub fn from_sections(
        sections: &[RawSection],
        plugins: impl PluginGroup,
    ) -> Result<Self, LoadErrorKind> {
        let corrupt = |section: &str, message: String| LoadErrorKind::Corrupt {
            section: section.to_string(),
            message,
        };
        let find = |name: &str| sections.iter().find(|s| s.name == name);
        // The bootstrap sections are read before the registry exists: check their versions here.
        for s in sections {
            if (s.name == "core.params" || s.name == "core.mesh") && s.version > 1 {
                return Err(LoadErrorKind::NewerSection {
                    section: s.name.clone(),
                    found: s.version,
                    supported: 1,
                });
            }
        }
        // Bootstrap: parameters and mesh recipe, needed to build the world.
        let params_s = find("core.params")
            .ok_or_else(|| LoadErrorKind::MissingSection("core.params".into()))?;
        let params = parse_params(&params_s.data)?;
        let mesh_s =
            find("core.mesh").ok_or_else(|| LoadErrorKind::MissingSection("core.mesh".into()))?;
        let recipe = read_recipe(&mut SectionReader::new(&mesh_s.data))
            .map_err(|e| corrupt("core.mesh", e.to_string()))?;
        let expected = MeshRecipe {
            samples: params.planet.samples,
            jitter: params.planet.sample_jitter,
            seed: params.planet.seed,
            radius_km: params.planet.radius_km,
            triangles: recipe.triangles,
            fingerprint: recipe.fingerprint,
        };
        if recipe != expected {
            return Err(corrupt(
                "core.mesh",
                format!("mesh recipe {recipe:?} does not match the saved parameters"),
            ));
        }
        let mesh = init::reference_mesh(&params).map_err(LoadErrorKind::Mesh)?;
        let rebuilt = recipe_of(&params, &mesh);
        if rebuilt.fingerprint != recipe.fingerprint || rebuilt.triangles != recipe.triangles {
            return Err(LoadErrorKind::MeshMismatch(format!(
                "the reference mesh this program builds for these parameters ({} triangles, fingerprint {:#018x}) differs from the one the save was made on ({} triangles, fingerprint {:#018x}): the save comes from a program whose mesh construction differs",
                rebuilt.triangles, rebuilt.fingerprint, recipe.triangles, recipe.fingerprint
            )));
        }
        let mut sim =
            Simulation::from_parts(params, mesh, plugins).map_err(LoadErrorKind::Schedule)?;
        let registry: Vec<SaveSection> = sim
            .world()
            .get_resource::<SaveRegistry>()
            .map(|r| r.sections().to_vec())
            .unwrap_or_default();
        if let Some(s) = sections
            .iter()
            .find(|s| !registry.iter().any(|r| r.name == s.name))
        {
            return Err(LoadErrorKind::UnknownSection(s.name.clone()));
        }
        for reg in &registry {
            match find(reg.name) {
                Some(s) => {
                    if s.version > reg.version {
                        return Err(LoadErrorKind::NewerSection {
                            section: s.name.clone(),
                            found: s.version,
                            supported: reg.version,
                        });
                    }
                    if s.version == 0 {
                        return Err(corrupt(reg.name, "section version 0 is invalid".into()));
                    }
                    let mut r = SectionReader::new(&s.data);
                    (reg.load)(sim.world_mut(), &mut r, s.version)
                        .map_err(|e| corrupt(reg.name, e.to_string()))?;
                }
                None => match reg.default {
                    Some(d) => d(sim.world_mut()).map_err(|e| corrupt(reg.name, e.to_string()))?,
                    None => return Err(LoadErrorKind::MissingSection(reg.name.into())),
                },
            }
        }
        sim.finish_load();
        Ok(sim)
    }
}
