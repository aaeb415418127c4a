//! Model parameters of the tectonic planet generator: one [`Params`] struct with every constant
//! in physical units, generated from a single declaration table together with its schema
//! (`schema`), dotted-key access and validation. Reading TOML files and printing the commented
//! TOML are in [`file`].

mod file;
mod schema;

pub(crate) use file::parse_toml_table;
pub use file::{PLUGINS_TABLE, read_param_file};
pub use schema::{ParamError, ParamKind, ParamSpec, ParamValue};
pub(crate) use schema::{
    check_value, describe_toml, from_toml_value, levenshtein, suggest_threshold,
};
use schema::{describe_value, spec_index, unknown_key};

/// Helpers to map the declared Rust type of a field onto the parameter kinds.
trait ParamType: Sized + Copy {
    fn to_value(self) -> ParamValue;
    fn from_value(v: ParamValue) -> Option<Self>;
}

impl ParamType for f64 {
    fn to_value(self) -> ParamValue {
        ParamValue::Float(self)
    }
    fn from_value(v: ParamValue) -> Option<Self> {
        match v {
            ParamValue::Float(x) => Some(x),
            _ => None,
        }
    }
}

impl ParamType for u64 {
    fn to_value(self) -> ParamValue {
        ParamValue::Int(self)
    }
    fn from_value(v: ParamValue) -> Option<Self> {
        match v {
            ParamValue::Int(x) => Some(x),
            _ => None,
        }
    }
}

impl ParamType for bool {
    fn to_value(self) -> ParamValue {
        ParamValue::Bool(self)
    }
    fn from_value(v: ParamValue) -> Option<Self> {
        match v {
            ParamValue::Bool(x) => Some(x),
            _ => None,
        }
    }
}

/// Kind of a declared field type (const context).
macro_rules! param_kind {
    (f64) => {
        ParamKind::Float
    };
    (u64) => {
        ParamKind::Int
    };
    (bool) => {
        ParamKind::Bool
    };
}

/// A `ParamValue` from a literal of a declared field type (const context).
macro_rules! param_value {
    (f64, $v:expr) => {
        ParamValue::Float($v)
    };
    (u64, $v:expr) => {
        ParamValue::Int($v)
    };
    (bool, $v:expr) => {
        ParamValue::Bool($v)
    };
}

/// A bound as `f64` for `ParamSpec::min`/`max` (const context).
macro_rules! bound_f64 {
    (f64, $v:expr) => {
        $v
    };
    (u64, $v:expr) => {{
        const V: u64 = $v;
        V as f64
    }};
    (bool, $v:expr) => {{
        const V: bool = $v;
        V as u8 as f64
    }};
}

/// Declares every section and field once and generates the structs, `Default`,
/// the schema, exact typed bounds, and dotted-key get/set.
macro_rules! define_params {
    ($(
        $(#[doc = $sdoc:literal])*
        [$sec:ident] $Sec:ident {
            $( $name:ident : $ty:ident = $def:literal,
               $min:literal ..= $max:literal, $unit:literal, $doc:literal; )*
        }
    )*) => {
        $(
            $(#[doc = $sdoc])*
            #[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
            #[serde(default, deny_unknown_fields)]
            pub struct $Sec {
                $(
                    #[doc = concat!($doc, " Unit: ", $unit, "; range ", stringify!($min), "..=", stringify!($max), "; default ", stringify!($def), ".")]
                    pub $name: $ty,
                )*
            }

            impl Default for $Sec {
                fn default() -> Self {
                    Self { $( $name: $def, )* }
                }
            }
        )*

        /// All model parameters, grouped by section, in physical units.
        #[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize, bevy_ecs::resource::Resource)]
        #[serde(default, deny_unknown_fields)]
        pub struct Params {
            $(
                $(#[doc = $sdoc])*
                pub $sec: $Sec,
            )*
        }

        impl Default for Params {
            fn default() -> Self {
                Self { $( $sec: $Sec::default(), )* }
            }
        }

        /// The schema, in declaration order.
        static SCHEMA: &[ParamSpec] = &[
            $( $(
                ParamSpec {
                    key: concat!(stringify!($sec), ".", stringify!($name)),
                    section: stringify!($sec),
                    name: stringify!($name),
                    kind: param_kind!($ty),
                    unit: $unit,
                    doc: $doc,
                    default: param_value!($ty, $def),
                    min: bound_f64!($ty, $min),
                    max: bound_f64!($ty, $max),
                },
            )* )*
        ];

        /// Exact typed bounds, parallel to `SCHEMA`.
        static BOUNDS: &[(ParamValue, ParamValue)] = &[
            $( $( (param_value!($ty, $min), param_value!($ty, $max)), )* )*
        ];

        /// Section names in declaration order.
        static SECTIONS: &[&str] = &[ $( stringify!($sec), )* ];

        impl Params {
            /// Reads a field by its full dotted key.
            fn get_field(&self, key: &str) -> Option<ParamValue> {
                $( $(
                    if key == concat!(stringify!($sec), ".", stringify!($name)) {
                        return Some(ParamType::to_value(self.$sec.$name));
                    }
                )* )*
                None
            }

            /// Stores an already checked value of the right kind; false if the key
            /// is unknown or the kind does not match.
            fn put_field(&mut self, key: &str, value: ParamValue) -> bool {
                $( $(
                    if key == concat!(stringify!($sec), ".", stringify!($name)) {
                        return match <$ty as ParamType>::from_value(value) {
                            Some(v) => { self.$sec.$name = v; true }
                            None => false,
                        };
                    }
                )* )*
                false
            }
        }
    };
}

define_params! {
    /// Planet geometry and sampling.
    [planet] Planet {
        radius_km: f64 = 6370.0, 100.0..=100000.0, "km", "Planet radius R (paper Appendix A).";
        samples: u64 = 500000, 1000..=4000000, "", "Number of crust samples on the sphere (Fibonacci points).";
        seed: u64 = 1, 0..=9223372036854775807, "", "Random seed: the same seed and parameters give the same planet at every resolution.";
        sample_jitter: f64 = 0.3, 0.0..=0.9, "fraction of spacing", "Random displacement of each Fibonacci sample, as a fraction of the mean sample spacing.";
    }
    /// Time stepping.
    [time] Time {
        time_step_my: f64 = 2.0, 0.1..=10.0, "My", "Time step δt (paper Appendix A).";
        relief_interval_steps: u64 = 2, 1..=16, "steps", "The climate and the drainage network are built again every this many steps (and on the step after each resampling), and the sediment lays down, with each new network, the rock eroded since the last one. The rivers and coasts wear the land every step, on the last network. 2 (the default) takes about four fifths of the relief sets' time of 1 (every step) for the same relief within Earth's bands, with slightly more lakes (docs/relief.md).";
    }
    /// Initial planet state.
    [init] Init {
        plates: u64 = 40, 2..=2000, "", "Initial number of plates.";
        continental_fraction: f64 = 0.3, 0.0..=0.95, "fraction of area", "Target fraction of the surface covered by continental crust at start.";
        border_warp_km: f64 = 600.0, 0.0..=3000.0, "km", "Amplitude of the low-frequency noise that warps the Voronoi plate borders (replaces Driftworld's mesh-based vector noise n_sm and border shifts n_vb, which depend on resolution).";
        border_warp_wavelength_km: f64 = 3000.0, 100.0..=40000.0, "km", "Wavelength of the plate-border warping noise.";
        continent_wavelength_km: f64 = 4000.0, 100.0..=40000.0, "km", "Wavelength of the noise that shapes the initial coastlines.";
        continental_elevation_km: f64 = 0.4, -2.0..=5.0, "km", "Mean initial elevation of continental crust (Driftworld z_0c = 0.8 km; 0.4 km stands the interiors of the first continents about where Earth's cratons stand).";
        oceanic_elevation_km: f64 = -4.0, -10.0..=0.0, "km", "Mean initial elevation of oceanic crust (Driftworld z_0t and its average ocean depth).";
        elevation_noise_km: f64 = 0.4, 0.0..=5.0, "km", "Amplitude of the low-frequency noise on initial elevations.";
        continental_thickness_km: f64 = 35.0, 1.0..=100.0, "km", "Initial thickness of continental crust.";
        margin_thinning_km: f64 = 12.0, 0.0..=100.0, "km", "The first continents' crust is thinned by this much at the coastline, less inland (like a rifted margin), so their coasts step down to the sea instead of ending in a cliff; never below 5 km. (Until 2026-12-06 rifting.margin_thinning_km set it.)";
        oceanic_thickness_km: f64 = 7.0, 1.0..=100.0, "km", "Thickness of oceanic crust, initial and newly formed (Driftworld's basic thickness e_0).";
        flood_fill: bool = false, false..=true, "", "Start method: false = warped Voronoi plates with continents from a noise field; true = plates grown from their seed points over the sample graph (seed 003), in an order drawn from a noise field on positions (so every resolution grows the same plates), each plate continental or oceanic as a whole (plates in a random order are continental until continental_fraction of the area is). CLI: --init voronoi|flood-fill.";
        flood_fill_roughness: f64 = 1.0, 0.0..=5.0, "", "Flood fill: how much the growth speed varies from place to place (cost of a km = exp(roughness × noise)); 0 grows plain geodesic Voronoi cells, larger values more ragged plates.";
        craters: u64 = 0, 0..=100000, "", "Impact craters struck into the initial crust (seed 004's late heavy bombardment; 0 = none). Each digs a bowl and throws the same volume out as an ejecta blanket beyond its rim; younger craters overprint older ones. CLI: --craters N.";
        crater_min_radius_km: f64 = 200.0, 10.0..=5000.0, "km", "Smallest crater radius (seed 004: 200 km). Radii follow N(> R) ∝ R⁻² between the smallest and the largest.";
        crater_max_radius_km: f64 = 2500.0, 10.0..=5000.0, "km", "Largest crater radius (seed 004: 2,500 km).";
        map_continental_above_m: f64 = -1000.0, -11000.0..=9000.0, "m", "In a start from a map (--from-heightmap, --from-earth): crust above this elevation is continental, below it oceanic (-1,000 m keeps the continental shelves and the upper slopes continental; Earth's continent-ocean boundary lies near the foot of the slope, -2,000 to -3,000 m, our age-depth law reaches -2,600 m at the ridge).";
        crater_depth_ratio: f64 = 0.05, 0.0..=0.5, "fraction of radius", "Thickness of crust a crater's bowl removes at its centre, as a fraction of its radius (seed 004: 1/20), falling off as 1 − (r/R)² to the rim; at least 1 km of crust is left.";
    }
    /// Plate motion.
    [plates] Plates {
        max_speed_mm_per_yr: f64 = 100.0, 1.0..=1000.0, "mm/yr", "Maximum plate surface speed v0 (paper Appendix A).";
        min_speed_fraction: f64 = 0.1, 0.0..=1.0, "fraction of v0", "Initial plate speeds are drawn uniformly between this fraction of v0 and v0.";
        momentum: bool = false, false..=true, "", "Plates carry angular momentum (mass from area and crust thickness, seed 004): a sutured terrane takes its momentum to the plate it joins, a collision exchanges momentum between the two plates, a rift's fragments keep the parent's total. Off: purely kinematic motions (the paper's).";
        collision_coupling: f64 = 0.5, 0.0..=1.0, "", "With plates.momentum: the fraction of the two plates' relative angular velocity a collision (suture) takes away (0: only the terrane's momentum moves; 1: the plates lock together).";
    }
    /// Oceanic crust.
    [ocean] Ocean {
        ridge_elevation_km: f64 = -1.0, -10.0..=0.0, "km", "Highest oceanic ridge elevation z_r.";
        abyssal_elevation_km: f64 = -6.0, -15.0..=0.0, "km", "Abyssal plain elevation z_a.";
        trench_elevation_km: f64 = -10.0, -20.0..=0.0, "km", "Oceanic trench elevation z_t.";
        damping_mm_per_yr: f64 = 0.04, 0.0..=10.0, "mm/yr", "Oceanic elevation damping ε_o.";
        sediment_accretion_mm_per_yr: f64 = 0.3, 0.0..=10.0, "mm/yr", "Sediment accretion in trenches ε_t.";
    }
    /// Continental crust.
    [continent] Continent {
        max_elevation_km: f64 = 10.0, 1.0..=30.0, "km", "Highest continental altitude z_c.";
        erosion_mm_per_yr: f64 = 0.03, 0.0..=10.0, "mm/yr", "Continental erosion ε_c.";
    }
    /// Subduction.
    [subduction] Subduction {
        distance_km: f64 = 900.0, 10.0..=10000.0, "km", "Subduction distance r_s: reach of the uplift on the overriding plate (paper: 1800 km; 900 km keeps active margins 200–750 km wide, as the Andes, DESIGN §7).";
        control_distance_km: f64 = 300.0, 1.0..=10000.0, "km", "Distance from the front where subduction uplift peaks (Driftworld: r_c = 0.1 R = 637 km; 300 km puts the range about where arcs stand, 200 km behind the trench, DESIGN §7).";
        uplift_mm_per_yr: f64 = 1.1, 0.0..=100.0, "mm/yr", "Base subduction uplift u0 (paper: 0.6 mm/yr). With isostasy on, the surface rise before compensation: the crust thickens by u/(1 − ρ_c/ρ_m). 1.1 since the trench follows the floor's path to the overriding plate (2026-12-05; 1.05 with collisions sutured in place, 0.9 before).";
        fold_weight: f64 = 0.1, 0.0..=10.0, "", "β: weight of the relative plate velocity in the fold direction update.";
        slab_pull_perturbation: f64 = 1.0, 0.0..=100.0, "", "Slab pull ε: the Euler pole of a subducting plate turns by 0.01·ε rad/My per radian of subduction front (normalised by front length, so independent of the sample count).";
        trench_width_km: f64 = 200.0, 1.0..=2000.0, "km", "Width of the trench on the subducting plate in front of a subduction front.";
        trench_rate: f64 = 1.0, 0.0..=1.0, "fraction per step", "Fraction of the gap to the trench profile (z_t at the front, z_a at the trench edge) closed each step (1: the plate bends down at once as it reaches the trench).";
        min_convergence_mm_per_yr: f64 = 5.0, 0.0..=1000.0, "mm/yr", "Plate boundaries converging slower than this make no subduction front.";
    }
    /// Continental collision.
    [collision] Collision {
        distance_km: f64 = 1500.0, 10.0..=20000.0, "km", "Maximum collision influence distance r_c (paper: 4200 km, which thickens whole continents; 1500 km makes Himalayan belts and plateaus of Tibet's size).";
        coefficient_per_km: f64 = 1.3e-5, 0.0..=1.0, "1/km", "Discrete collision coefficient Δ_c.";
        interpenetration_km: f64 = 300.0, 0.0..=5000.0, "km", "Interpenetration of continental crust that triggers a collision.";
        trapped_ocean_km2: f64 = 50000.0, 0.0..=1e8, "km²", "A patch of oceanic crust smaller than this, enclosed by the continental crust of one plate (an ocean closed by a collision), is welded into the continent at the next resampling.";
        min_terrane_km2: f64 = 100000.0, 0.0..=1e9, "km²", "A continent smaller than this does not collide as one (paper §4.1): meeting a larger one it docks onto it at the next resampling (collision.docking), else it is forced under and counted as subducted continental crust.";
        docking: bool = false, false..=true, "", "Island arcs (oceanic crust at least collision.arc_min_thickness_km thick) and microcontinents (smaller than collision.min_terrane_km2) that reach a continent at a front dock onto it at the next resampling (paper Fig. 15): they join its plate, arcs becoming continental crust at their elevation, with a suture. Off: they are forced under, as in the paper.";
        arc_min_thickness_km: f64 = 30.0, 1.0..=100.0, "km", "Oceanic crust at least this thick (mature island arcs and oceanic plateaus: the Aleutian arc is 30-35 km thick, Ontong Java 30-35 km; normal oceanic crust is init.oceanic_thickness_km) docks onto a continent instead of subducting (collision.docking). 20 km lets thick sediment piles dock too and grows the continents by 10-18% in 250 My; 12 km by half.";
        resample_at_suture: bool = false, false..=true, "", "Off (the default since 2026-12-05): the terrane leaves its plate at once as a plate of its own, keeping its place and moving with the plate it joins, and sutures at the next regular resampling (14 resamplings in the default 250 My instead of 33, about a quarter faster; docs/performance.md). On: every collision forces a global resampling in its step, where its terrane joins the other plate (the paper's way; always so with plates.momentum).";
        max_uplift_km: f64 = 0.5, 0.0..=30.0, "km", "Saturation of the collision surge: Δz = H·(1 − exp(−Δ_c·A/H)), Δ_c·A for small terranes, at most H for continents (with isostasy on, the crust thickens by Δz/(1 − ρ_c/ρ_m): 3.3 km at 0.5 km, and collisions repeat).";
    }
    /// Isostasy: surface elevation from crust thickness (continents, regional Airy) and from
    /// sea-floor age (ocean, plate cooling); the trench in front of each subduction front.
    [isostasy] Isostasy {
        crust_density_g_per_cm3: f64 = 2.8, 1.0..=5.0, "g/cm³", "Density of the crust ρ_c (DESIGN §7).";
        mantle_density_g_per_cm3: f64 = 3.3, 1.5..=6.0, "g/cm³", "Density of the mantle ρ_m (DESIGN §7); 1 km of extra crust raises the surface by 1 − ρ_c/ρ_m km.";
        sediment_density_g_per_cm3: f64 = 2.5, 1.1..=5.0, "g/cm³", "Density of marine sediment ρ_s (compacted; Sclater & Christie 1980): oceanic crust thicker than init.oceanic_thickness_km (sediment, arcs, edifices) raises the sea floor by (ρ_m − ρ_s)/(ρ_m − ρ_w) of the excess.";
        reference_thickness_km: f64 = 35.0, 1.0..=100.0, "km", "Thickness T₀ of the reference continental column.";
        reference_elevation_km: f64 = 0.3, -5.0..=5.0, "km", "Surface elevation h₀ of the reference continental column (thickness T₀): sets where continents stand relative to the sea.";
        elastic_thickness_km: f64 = 25.0, 0.0..=200.0, "km", "Elastic thickness T_e of the lithosphere: the width of the regional response (flexure) that holds a range up with the crust around it (Watts 2001; continents 5–100 km). 0: local Airy.";
        max_flexural_support_km: f64 = 1.5, 0.0..=50.0, "km", "Most the regional response holds a sample above, or pulls it below, its local Airy level (a narrow range stands higher than Airy, the sea floor beside a continent sinks into a moat): it keeps one-sample contrasts (a lake filled with sediment, a sliver of thick crust) from standing kilometres proud over a moat as deep.";
        parsons_sclater: bool = false, false..=true, "", "Ocean depth by Parsons & Sclater 1977 (2.5 + 0.35·√t, then 6.4 − 3.2·e^(−t/62.8)) instead of GDH1 (Stein & Stein 1992: 2.6 + 0.365·√t, then 5.651 − 2.473·e^(−0.0278·t)).";
        ridge_depth_offset_km: f64 = 0.0, -3.0..=3.0, "km", "Added to the age–depth law's depth (0: the published law, ridges at −2.6 km for GDH1; 0.2 puts them at the observed −2.8 km, DESIGN §7, but pelagic sediment aside, old floor then stands deeper than observed).";
        trench_depth_km: f64 = 3.5, 0.0..=15.0, "km", "Depth of a trench below the sea floor beside it, at the subduction front (observed 3–4 km, DESIGN §7).";
        trench_width_km: f64 = 80.0, 1.0..=2000.0, "km", "Distance from the front over which the trench shallows to the sea floor on either side (profile (1 − |d|/w)²: about 50 km wide at half depth; observed trenches are 40–120 km wide, DESIGN §7).";
        max_thickness_km: f64 = 75.0, 10.0..=300.0, "km", "Subduction and collisions never thicken continental crust beyond this (about 6.4 km of elevation under Airy isostasy at the defaults; the crust of Tibet is about 70 km thick), and isostasy floats no more than this: a column made thicker by sediment or resampling stands where one this thick would (over-thickened roots delaminate: Kay & Kay 1993).";
        max_oceanic_thickness_km: f64 = 30.0, 1.0..=300.0, "km", "Subduction never thickens oceanic crust (island arcs) beyond this (about +3 km on old sea floor at the defaults; real arcs have 20–35 km of crust), and isostasy counts no more load on oceanic crust than this thickness gives: a thicker sediment pile stands where this one would.";
        ocean_volume_layer_km: f64 = 0.0, 0.0..=10.0, "km", "Water of the ocean, as the depth of a layer over the whole globe (Earth: 1.335·10⁹ km³, a layer 2.62 km deep; Charette & Smith 2010). The sea level follows from it: after each isostasy pass the surface moves against the sea until the water below sea level has this volume, so shallower basins (young floor, arcs, sediment) or higher continents raise the sea and flood the lowest land, and deeper basins lower it (its shift is `sea_level_m` in summary.json). 0: the sea stays at the isostatic datum, whatever the water.";
    }
    /// Rivers: the drainage network, stream-power incision and hillslope diffusion.
    [rivers] Rivers {
        erodibility_per_my: f64 = 1.8, 0.0..=1000.0, "km^(1−2m)/My", "Erodibility K of stream power E = K·A^m·S^n − E_c (A in km² weighted by the rain, S in m/m, E in km/My). For m = 0.5, K = 1 is 1e−6/yr in SI (typical 1e−7…1e−5: Stock & Montgomery 1999). Calibrated with the climate on and endorheic basins filling from their floor (docs/relief.md); 2.4 until 2026-12-06, when rifts that hold left fewer sutures and less ground above 3 km (a lower K raises the ranges without more rock reaching the sea in the long run, which more uplift would).";
        area_exponent: f64 = 0.5, 0.0..=2.0, "", "Exponent m of drainage area (m/n ≈ 0.5: Whipple & Tucker 1999).";
        slope_exponent: f64 = 1.0, 0.25..=4.0, "", "Exponent n of slope.";
        incision_threshold_mm_per_yr: f64 = 0.3, 0.0..=100.0, "mm/yr", "Incision threshold E_c: old ranges stop eroding once their stream power falls under it, so they persist (Baldwin, Whipple & Tucker 2003; Tucker & Bras 2000).";
        reference_spacing_km: f64 = 50.0, 1.0..=1000.0, "km", "Drainage areas are scaled by (this / mean sample spacing), so relief does not depend on the resolution (a width-normalised area).";
        hillslope_diffusivity_km2_per_my: f64 = 30.0, 0.0..=100000.0, "km²/My", "Diffusivity κ of the land surface (landscape scale; Culling 1960).";
        min_sea_area_km2: f64 = 250000.0, 0.0..=1e9, "km²", "A body of water below sea level smaller than this, or without oceanic crust, is a lake: it fills with sediment and overflows toward the sea instead of taking the sediment of the land around it (the Caspian is 370,000 km²).";
        denudation_per_my: f64 = 0.05, 0.0..=10.0, "1/My", "Background denudation: land loses this fraction of its height above sea level per My, up to denudation_cap_km (weathering and transport below the resolution of the network, which stream power with its threshold leaves out), carried down the network as sediment. 0.05/My is 0.05 mm/yr at 1 km, within the rates of old orogens and cratons (0.01–0.1 mm/yr, Portenga & Bierman 2011); with isostatic rebound, a plain left alone sinks toward sea level over about 130 My.";
        denudation_cap_km: f64 = 1.0, 0.0..=20.0, "km", "Background denudation grows with height up to this elevation and no further: ranges are worn by rivers (stream power), lowlands by denudation.";
        runoff_mm_per_yr: f64 = 300.0, 0.0..=10000.0, "mm/yr", "Runoff over the land (rain less evapotranspiration; Earth's mean is about 300 mm/yr: Fekete, Vörösmarty & Grabs 2002), scaled by the precipitation field where a plugin sets one. With lake_net_evaporation_mm_per_yr it sets how much lake a closed depression keeps.";
        lake_net_evaporation_mm_per_yr: f64 = 1000.0, 0.0..=10000.0, "mm/yr", "Evaporation from a lake surface less the rain on it (about 1 m/yr for the Caspian, the Great Salt Lake and the Dead Sea). A lake larger than runoff / this × its catchment cannot be kept full: it shrinks to that area, holds no outlet, and its basin drains into it (an endorheic basin). 0: every depression fills to its spill point and overflows.";
    }
    /// Climate: rain over the land from the planet's winds (phenomenon `climate`, see
    /// `systems::relief::climate`): a zonal pattern, moisture carried inland by the prevailing
    /// winds, rain shadows behind ranges and more rain on windward slopes. The drainage areas
    /// (and so the rivers' power and the lakes' water) follow it; its mean over the land is 1.
    [climate] Climate {
        moisture_length_km: f64 = 1500.0, 10.0..=100000.0, "km", "Distance from the sea over which the moisture carried inland falls by e (continental interiors 2,000 km from the sea, Central Asia, get a fifth of a coast's rain; on Earth recycling by vegetation carries rain farther, as over the Amazon).";
        wind_anisotropy: f64 = 0.6, 0.0..=0.95, "", "How much easier moisture travels with the prevailing wind than across it: an edge costs its length times 1 − a·cos(angle to the wind), so with 0.6 an edge downwind costs a quarter of one upwind (the west coasts of the mid-latitudes and the east coasts of the trade-wind belts are wet). 0: no wind.";
        orographic_height_km: f64 = 1.0, 0.0..=100.0, "km", "Climb over which air loses as much moisture as over moisture_length_km of flat land: air forced over a range rains out on the way up and leaves a rain shadow behind (the Andes over Patagonia, the Himalaya over Tibet). 0: no rain shadow.";
        windward_slope: f64 = 0.004, 0.0..=1.0, "m/m", "Windward slope that doubles the rain (orographic rain, at most three times that of flat ground; 0: none). Slopes are measured between samples, so this is the slope of a range side tens of km across.";
        min_rain: f64 = 0.1, 0.0..=1.0, "", "The least rain anywhere on land, as a fraction of the land's mean (deserts get a tenth of it or less, but a floor keeps the rivers of dry plateaus eroding over hundreds of My; the mean then stands a little above 1).";
    }
    /// Coasts: waves cut back coasts that face open water and leave a platform below sea level,
    /// which sediment builds into a shelf.
    [coasts] Coasts {
        retreat_km_per_my: f64 = 120.0, 0.0..=1000.0, "km/My", "Retreat rate of a coast facing open water with no shallow platform in front (1 km/My = 1 mm/yr). Hard rock coasts retreat 1–10 mm/yr, soft ones 0.1–1 m/yr (Sunamura 1992); a sample-wide coast mixes both, and the rate falls off fast as the platform widens. Calibrated at 100k samples: 2, 20, 60 and 200 km/My gave 1.3, 1.8, 2.3 and 2.6% of the globe between −200 m and sea level at 250 My (mean of seeds 1, 2, 3, 7); 120 instead of 60 since 2026-12-05 (16 runs: the band at least 3% on 13 runs instead of 11, nothing else changed its verdict).";
        damping_width_km: f64 = 100.0, 1.0..=10000.0, "km", "Width of shallow water over which the retreat rate falls by e: waves spend their energy crossing a wide platform, so the platform widens ever more slowly (Trenhaile 2000). On Earth the damping acts over kilometres of platform; here a sample is 30–70 km wide, so the width is that of a few samples.";
        wave_base_m: f64 = 50.0, 0.0..=500.0, "m", "Depth the waves plane the platform down to (fair-weather to storm wave base, 10–100 m).";
        open_water_depth_m: f64 = 200.0, 1.0..=5000.0, "m", "Water deeper than this is open sea: the width of shallower water in front of a coast is measured from it.";
    }
    /// Sediment: what rivers carry is laid down in lakes, on shelves, slopes and rises, and in
    /// trenches and basins.
    [sediment] Sediment {
        coast_depth_km: f64 = 0.01, 0.0..=1.0, "km", "Water depth of the shelf surface at the shoreline.";
        shelf_gradient: f64 = 0.0017, 0.0..=0.1, "m/m", "Gradient of the shelf (0.1°, DESIGN §7).";
        shelf_break_depth_km: f64 = 0.13, 0.0..=2.0, "km", "Depth of the shelf break (about 130 m, DESIGN §7).";
        outer_shelf_gradient: f64 = 0.0004, 0.0..=0.1, "m/m", "Gradient of the shelf top beyond the break depth (keeps sediment moving seaward).";
        slope_gradient: f64 = 0.052, 0.001..=1.0, "m/m", "Gradient of the continental slope (3°, DESIGN §7).";
        slope_base_depth_km: f64 = 2.5, 0.1..=10.0, "km", "Depth of the foot of the continental slope, where the rise begins.";
        rise_gradient: f64 = 0.0087, 0.0..=1.0, "m/m", "Gradient of the continental rise (0.5°).";
        pelagic_rate_m_per_my: f64 = 14.0, 0.0..=1000.0, "m/My", "Pelagic sediment (plankton shells, dust) settling on the sea floor, which raises it by (ρ_m − ρ_s)/(ρ_m − ρ_w) of the layer (typical 1–10 m/My, more above the carbonate compensation depth).";
        graded_slope: f64 = 0.0, 0.0..=0.1, "m/m", "Graded slope of a river draining 1,000 km² (0, the default: off): where the ground falls less steeply than that to the next sample downstream (or to the sea), the river lays down what it carries until it does, so subsiding lowlands and deltas build into alluvial plains that rise gently inland. Lowland rivers fall 10⁻⁵ (the Amazon) to 10⁻³ (small rivers). Off by default: at 0.001, over seeds 1, 2, 3 and 7 at 100k samples and 250 My, the plains took 6% of the sediment and the land fraction rose by 0.01–0.03 while the −200..0 m band fell from 4.7–7.0% to 2.2–3.7% of the globe (the plains are built where shallow sea stood).";
        graded_concavity: f64 = 0.45, 0.0..=1.0, "", "How fast the graded slope falls with drainage area A: S = graded_slope·(A / 1,000 km²)^(−θ) (θ ≈ 0.45 fits 10⁻³ at 1,000 km² and 2·10⁻⁵ at the Amazon's 6 million).";
        pelagic_min_depth_m: f64 = 50.0, 0.0..=6000.0, "m", "Pelagic sediment settles only where the sea is deeper than this (the storm wave base: shallower water keeps the fine rain in suspension and carries it off). Without it, floor filled to sea level flickered across it, raised at sea by the rain and lowered on land by its age, and drew stripes of land and water along prograding coasts.";
        pelagic_max_age_my: f64 = 150.0, 0.0..=10000.0, "My", "Pelagic sediment settles on sea floor younger than this (old floor lies below the carbonate compensation depth, where little settles), which bounds the layer to rate × age.";
        pelagic_ccd_m: f64 = 0.0, 0.0..=11000.0, "m", "Carbonate compensation depth (CCD): below it the shells of the pelagic rain dissolve before they settle and only clay (`pelagic_clay_rate_m_per_my`) is laid; over the 1 km above it (the lysocline to the CCD) the rain falls linearly from `pelagic_rate_m_per_my` to the clay's. Earth: 4.2–5 km (Pacific to Atlantic). 0: off, the full rain at every depth.";
        pelagic_clay_rate_m_per_my: f64 = 1.0, 0.0..=1000.0, "m/My", "Pelagic clay (dust, the shells' insoluble remains) laid below the carbonate compensation depth (`pelagic_ccd_m`; abyssal red clay builds at 0.5–2 m/My).";
        pelagic_variability: f64 = 0.0, 0.0..=3.0, "", "How much the pelagic rain varies from place to place (0, the default: the same everywhere): the rate is multiplied by exp(σ·F), F a smooth noise field of unit spread fixed in the mantle frame, scaled so the rain's mean over the globe stays `pelagic_rate_m_per_my`. Earth's rates range tenfold, from red clay under the gyres to ooze under upwelling (σ ≈ 0.7 spans ×0.3 to ×3.2 between the 5th and 95th percentiles). It spreads the floor's depths (docs/relief.md, 2026-12-07).";
        pelagic_variability_km: f64 = 2000.0, 100.0..=40000.0, "km", "Wavelength of the noise field of `pelagic_variability` (its first octave, of three).";
        pelagic_variability_from_age_my: f64 = 0.0, 0.0..=10000.0, "My", "Age of the floor from which the pelagic rain varies (`pelagic_variability`); younger floor gets the mean rate everywhere. Young floor stands shallow, above the carbonate compensation depth, where shells settle at much the same rate everywhere; older floor sinks below it, where what settles depends on the plankton and dust overhead (siliceous ooze under upwelling, red clay under the gyres). 0: the rain varies at every age. `pelagic_rate.png` and the viewer's pelagic rain layer draw the field itself, the rain on floor of that age or older.";
    }
    /// Plate rifting.
    [rifting] Rifting {
        frequency_per_my: f64 = 0.002, 0.0..=10.0, "1/My", "Rifting rate λ0: expected rifting events per My of an all-continental plate of the reference area A0 = planet area / init.plates. Each plate is a Poisson process of λ = λ0·δt·f(x)·A/A0 rifts a step; the rifts of the steps since the last resampling are drawn and carried out on the step that ends with the next one (see systems::rifting).";
        oceanic_factor: f64 = 0.2, 0.0..=1.0, "", "f(0): the rifting rate of an all-oceanic plate relative to an all-continental one; f(x) = f(0) + (1 − f(0))·x for a continental share x.";
        min_plate_area_km2: f64 = 6.0e6, 0.0..=1e9, "km²", "Plates smaller than this never rift on their own.";
        max_fragments: u64 = 4, 2..=4, "", "A random rift splits a plate into 2 to this many fragments (paper: n ∈ [2, 4]).";
        divergence_speed_mm_per_yr: f64 = 25.0, 0.0..=1000.0, "mm/yr", "Mean speed at which the fragments move away from the parent's centroid (each in proportion to its distance from it, so every fracture opens), added to the parent's own motion.";
        fracture_warp_km: f64 = 400.0, 0.0..=3000.0, "km", "Amplitude of the noise that warps the Voronoi borders between fragments into irregular fracture lines.";
        sibling_grace_my: f64 = 30.0, 0.0..=10000.0, "My", "For this long after a rift, its fragments build no subduction front between them, so they neither subduct nor collide where the rotations that open their winding fracture close a stretch of it (there the resampling keeps one fragment's crust where they overlap). 0: siblings converge like any plates at once, and most rifts had a fragment's continent sutured back onto a sibling within the first resampling interval, leaving a low ridge along the closed stretch.";
        fracture_wavelength_km: f64 = 2500.0, 100.0..=40000.0, "km", "Wavelength of the fracture-warping noise.";
        margin_thinning_km: f64 = 0.0, 0.0..=100.0, "km", "Continental crust is thinned by this much at a new rift (stretching), less away from it, so a rifted margin steps down to the sea instead of ending in a cliff; never below 5 km. 0 (the default since 2026-12-06; 12 before): where the fragments did not part for good, the thinned strips stayed in the continents as narrow straight troughs held kilometres deep by the regional isostasy, with raised rims (up to 0.9% of the globe of continental crust below −2 km at 1000 My), and without them the relief is as close to Earth's (docs/relief.md).";
        margin_width_km: f64 = 200.0, 1.0..=3000.0, "km", "Width of the thinned margin on each side of a rift: the thinning falls as (1 − d/w)².";
    }
    /// Global resampling.
    [resample] Resample {
        min_interval_steps: u64 = 10, 1..=1000, "steps", "Fewest steps between two global resamplings.";
        max_interval_steps: u64 = 60, 1..=1000, "steps", "Most steps between two global resamplings.";
        adaptive_displacement_km: f64 = 2000.0, 1.0..=20000.0, "km", "Resample once the fastest plate has moved this far (clamped to the interval bounds); 10 steps at v0, as in the paper.";
        fragment_min_area_km2: f64 = 500000.0, 0.0..=1e9, "km²", "A disconnected piece of a plate smaller than this joins the neighbouring plate; a larger piece becomes a plate of its own.";
    }
}

/// Surface rise of dry crust per km of thickening under Airy isostasy, 1 − ρ_c/ρ_m (0.1515 at the
/// defaults; at least 0.001): the factor that turns the paper's uplift, a surface rise, into the
/// thickening that makes it.
pub fn dry_isostatic_gain(params: &Params) -> f64 {
    let i = &params.isostasy;
    (1.0 - i.crust_density_g_per_cm3 / i.mantle_density_g_per_cm3).max(1e-3)
}

/// Rise of the sea floor per km of crust above the normal oceanic thickness (sediment, arcs,
/// edifices), (ρ_m − ρ_s)/(ρ_m − ρ_w) (0.352 at the defaults; at least 0.001).
pub fn oceanic_load_gain(params: &Params) -> f64 {
    let i = &params.isostasy;
    ((i.mantle_density_g_per_cm3 - i.sediment_density_g_per_cm3)
        / (i.mantle_density_g_per_cm3 - 1.03).max(1e-6))
    .max(1e-3)
}

impl Params {
    /// Nominal thickness of crust of type `ct` (`init.continental_thickness_km` or
    /// `init.oceanic_thickness_km`), km: what new crust of that type is made with.
    pub fn nominal_thickness_km(&self, ct: crate::resources::CrustType) -> f64 {
        match ct {
            crate::resources::CrustType::Continental => self.init.continental_thickness_km,
            crate::resources::CrustType::Oceanic => self.init.oceanic_thickness_km,
        }
    }

    /// Every parameter, in declaration order (section by section).
    pub fn schema() -> &'static [ParamSpec] {
        SCHEMA
    }

    /// The current value of the parameter with the full dotted `key`
    /// (e.g. `"ocean.ridge_elevation_km"`), or `None` for an unknown key.
    pub fn get(&self, key: &str) -> Option<ParamValue> {
        self.get_field(key)
    }

    /// Sets a parameter by full dotted key after checking its type, finiteness and
    /// range. An `Int` is accepted for a float parameter; a `Float` is accepted for an
    /// integer parameter only if it is integral and non-negative. Cross-field checks
    /// are left to [`Params::validate`]. On error, `self` is unchanged.
    pub fn set(&mut self, key: &str, value: ParamValue) -> Result<(), ParamError> {
        let index = spec_index(key).ok_or_else(|| unknown_key(key))?;
        let (Some(spec), Some(bounds)) = (SCHEMA.get(index), BOUNDS.get(index)) else {
            return Err(unknown_key(key));
        };
        let checked = check_value(spec, *bounds, value)?;
        if self.put_field(key, checked) {
            Ok(())
        } else {
            Err(ParamError::WrongType {
                key: key.to_string(),
                expected: spec.kind,
                found: describe_value(value),
            })
        }
    }

    /// Checks every field (finiteness and range) and the cross-field constraints:
    /// `init.plates <= planet.samples / 20`,
    /// `ocean.trench_elevation_km < ocean.abyssal_elevation_km < ocean.ridge_elevation_km < 0`,
    /// `resample.min_interval_steps <= resample.max_interval_steps`,
    /// `init.oceanic_elevation_km < init.continental_elevation_km <= continent.max_elevation_km`,
    /// `subduction.control_distance_km < subduction.distance_km`,
    /// `init.crater_min_radius_km <= init.crater_max_radius_km`.
    pub fn validate(&self) -> Result<(), ParamError> {
        for (spec, bounds) in SCHEMA.iter().zip(BOUNDS) {
            if let Some(v) = self.get_field(spec.key) {
                check_value(spec, *bounds, v)?;
            }
        }
        let max_plates = self.planet.samples / 20;
        if self.init.plates > max_plates {
            return Err(ParamError::TooManyPlates {
                plates: self.init.plates,
                samples: self.planet.samples,
                max_plates,
            });
        }
        let o = &self.ocean;
        if !(o.trench_elevation_km < o.abyssal_elevation_km
            && o.abyssal_elevation_km < o.ridge_elevation_km
            && o.ridge_elevation_km < 0.0)
        {
            return Err(ParamError::OceanElevationOrder {
                trench: o.trench_elevation_km,
                abyssal: o.abyssal_elevation_km,
                ridge: o.ridge_elevation_km,
            });
        }
        let r = &self.resample;
        if r.min_interval_steps > r.max_interval_steps {
            return Err(ParamError::ResampleInterval {
                min: r.min_interval_steps,
                max: r.max_interval_steps,
            });
        }
        let ordered = [
            (
                ("init.oceanic_elevation_km", self.init.oceanic_elevation_km),
                (
                    "init.continental_elevation_km",
                    self.init.continental_elevation_km,
                ),
                true,
                "oceanic crust starts lower than continental crust",
            ),
            (
                (
                    "init.continental_elevation_km",
                    self.init.continental_elevation_km,
                ),
                (
                    "continent.max_elevation_km",
                    self.continent.max_elevation_km,
                ),
                false,
                "continents cannot start above the highest continental altitude",
            ),
            (
                (
                    "subduction.control_distance_km",
                    self.subduction.control_distance_km,
                ),
                ("subduction.distance_km", self.subduction.distance_km),
                true,
                "subduction uplift peaks inside its reach (the distance transfer divides by (r_s - r_c)³)",
            ),
            (
                ("init.crater_min_radius_km", self.init.crater_min_radius_km),
                ("init.crater_max_radius_km", self.init.crater_max_radius_km),
                false,
                "the smallest crater cannot be larger than the largest",
            ),
        ];
        for ((lower_key, lower), (upper_key, upper), strict, why) in ordered {
            if lower > upper || (strict && lower == upper) {
                return Err(ParamError::OutOfOrder {
                    lower_key,
                    lower,
                    upper_key,
                    upper,
                    strict,
                    why,
                });
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashSet;

    fn err(text: &str) -> ParamError {
        match Params::from_toml_str(text) {
            Ok(p) => panic!("expected an error for {text:?}, got {p:?}"),
            Err(e) => e,
        }
    }

    #[test]
    fn defaults_are_valid_and_round_trip() {
        let p = Params::default();
        p.validate().unwrap();
        let text = p.to_commented_toml();
        assert!(text.starts_with("# Parameters of the tectonic planet generator"));
        assert!(text.contains("radius_km = 6370.0\n"), "{text}");
        assert!(text.contains("coefficient_per_km = 1.3e-5\n"), "{text}");
        assert!(
            text.contains("# Planet radius R (paper Appendix A). [km] (range 100.0..100000.0)\n"),
            "{text}"
        );
        assert!(
            text.contains("# Initial number of plates. (range 2..2000)\n"),
            "{text}"
        );
        assert!(text.contains("(range 0..9223372036854775807)"), "{text}");
        let back = Params::from_toml_str(&text).unwrap();
        assert_eq!(back, p);
        // Every key is present in the printout.
        for spec in Params::schema() {
            assert!(
                text.contains(&format!("\n{} = ", spec.name)),
                "{}",
                spec.key
            );
            assert!(
                text.contains(&format!("\n[{}]\n", spec.section)),
                "{}",
                spec.section
            );
        }
    }

    #[test]
    fn non_default_values_round_trip_exactly() {
        let mut p = Params::default();
        p.collision.coefficient_per_km = 0.1 + 0.2; // 0.30000000000000004
        p.planet.radius_km = 1.0e5;
        p.planet.seed = 9_223_372_036_854_775_807;
        p.init.continental_elevation_km = -1.234_567_890_123_456_7;
        p.resample.fragment_min_area_km2 = 1e9;
        p.ocean.damping_mm_per_yr = 5e-324; // smallest subnormal
        p.validate().unwrap();
        let back = Params::from_toml_str(&p.to_commented_toml()).unwrap();
        assert_eq!(back, p);
    }

    #[test]
    fn partial_file_overrides_only_its_keys() {
        let p = Params::from_toml_str("[ocean]\nridge_elevation_km = -2.5\n[init]\nplates = 12\n")
            .unwrap();
        let mut expected = Params::default();
        expected.ocean.ridge_elevation_km = -2.5;
        expected.init.plates = 12;
        assert_eq!(p, expected);
        assert_eq!(Params::from_toml_str("").unwrap(), Params::default());
        // Dotted keys at top level are ordinary TOML too.
        let p = Params::from_toml_str("time.time_step_my = 1\n").unwrap();
        assert_eq!(p.time.time_step_my, 1.0);
    }

    #[test]
    fn integer_accepted_for_float_field() {
        let p = Params::from_toml_str("[planet]\nradius_km = 3000\n").unwrap();
        assert_eq!(p.planet.radius_km, 3000.0);
    }

    #[test]
    fn malformed_toml_reports_position() {
        let e = err("[planet]\nradius_km = = 3\n");
        assert!(
            matches!(e, ParamError::MalformedToml { line: Some(2), .. }),
            "{e:?}"
        );
        let msg = e.to_string();
        assert!(msg.starts_with("malformed TOML: "), "{msg}");
        assert!(msg.contains("column 13"), "{msg}");
        assert!(
            matches!(
                e,
                ParamError::MalformedToml {
                    column: Some(13),
                    ..
                }
            ),
            "{e:?}"
        );
        assert!(msg.contains("line 2"), "{msg}");
        // Duplicate keys are a TOML error too.
        let e = err("[init]\nplates = 3\nplates = 4\n");
        assert!(matches!(e, ParamError::MalformedToml { .. }), "{e:?}");
    }

    #[test]
    fn unknown_key_with_typo_suggests() {
        let e = err("[ocean]\nridge_elevaton_km = -1\n");
        assert!(
            matches!(&e, ParamError::UnknownKey { key, suggestion: Some(s) } if key == "ocean.ridge_elevaton_km" && s == "ocean.ridge_elevation_km"),
            "{e:?}"
        );
        assert_eq!(
            e.to_string(),
            "unknown parameter \"ocean.ridge_elevaton_km\"; did you mean \"ocean.ridge_elevation_km\"?"
        );
    }

    #[test]
    fn key_in_wrong_section_suggests_right_full_key() {
        let e = err("[planet]\nplates = 10\n");
        assert_eq!(
            e.to_string(),
            "unknown parameter \"planet.plates\"; did you mean \"init.plates\"?"
        );
        let e = err("[ocean]\nmax_elevation_km = 3\n");
        assert!(
            e.to_string()
                .contains("did you mean \"continent.max_elevation_km\"?"),
            "{e}"
        );
        // Top-level key without a section.
        let e = err("samples = 1000\n");
        assert_eq!(
            e.to_string(),
            "unknown parameter \"samples\"; did you mean \"planet.samples\"?"
        );
        // Via set() as well.
        let e = Params::default()
            .set("time.seed", ParamValue::Int(3))
            .unwrap_err();
        assert!(
            e.to_string().contains("did you mean \"planet.seed\"?"),
            "{e}"
        );
    }

    #[test]
    fn unknown_key_far_from_anything_has_no_suggestion() {
        let e = err("[ocean]\nzzzzzzzzzzzzzzzzzzzzz = 1\n");
        assert!(
            matches!(
                &e,
                ParamError::UnknownKey {
                    suggestion: None,
                    ..
                }
            ),
            "{e:?}"
        );
        assert_eq!(
            e.to_string(),
            "unknown parameter \"ocean.zzzzzzzzzzzzzzzzzzzzz\""
        );
    }

    #[test]
    fn unknown_section_suggests() {
        let e = err("[oceans]\nridge_elevation_km = -1\n");
        assert!(
            matches!(&e, ParamError::UnknownSection { section, suggestion: Some(s) } if section == "oceans" && s == "ocean"),
            "{e:?}"
        );
        assert_eq!(
            e.to_string(),
            "unknown parameter section [oceans]; did you mean \"ocean\"?"
        );
        let e = err("[qwertyuiop]\n");
        assert_eq!(e.to_string(), "unknown parameter section [qwertyuiop]");
    }

    #[test]
    fn section_given_as_value_is_rejected() {
        let e = err("ocean = 3\n");
        assert!(
            matches!(&e, ParamError::SectionNotTable { section, .. } if section == "ocean"),
            "{e:?}"
        );
        assert!(e.to_string().contains("integer 3"), "{e}");
    }

    #[test]
    fn wrong_types_are_rejected() {
        let e = err("[planet]\nradius_km = \"big\"\n");
        assert!(
            matches!(&e, ParamError::WrongType { key, expected: ParamKind::Float, .. } if key == "planet.radius_km"),
            "{e:?}"
        );
        assert_eq!(
            e.to_string(),
            "parameter \"planet.radius_km\" must be a number, got string \"big\""
        );
        let e = err("[planet]\nradius_km = { a = 1 }\n");
        assert!(e.to_string().contains("got a table"), "{e}");
        let e = err("[init]\nplates = [1, 2]\n");
        assert!(
            matches!(
                &e,
                ParamError::WrongType {
                    expected: ParamKind::Int,
                    ..
                }
            ),
            "{e:?}"
        );
        let e = err("[init]\nplates = true\n");
        assert!(
            e.to_string().contains("\"init.plates\"") && e.to_string().contains("boolean true"),
            "{e}"
        );
        // A sub-table inside a section.
        let e = err("[ocean.ridge_elevation_km]\nx = 1\n");
        assert!(
            matches!(&e, ParamError::WrongType { key, .. } if key == "ocean.ridge_elevation_km"),
            "{e:?}"
        );
    }

    #[test]
    fn float_for_int_field() {
        let e = err("[init]\nplates = 40.5\n");
        assert!(
            matches!(&e, ParamError::NotIntegral { key, value } if key == "init.plates" && *value == 40.5),
            "{e:?}"
        );
        assert_eq!(
            e.to_string(),
            "parameter \"init.plates\" must be an integer, got 40.5"
        );
        // Integral floats are accepted.
        let p = Params::from_toml_str("[init]\nplates = 30.0\n").unwrap();
        assert_eq!(p.init.plates, 30);
        let mut p = Params::default();
        p.set("init.plates", ParamValue::Float(25.0)).unwrap();
        assert_eq!(p.init.plates, 25);
        assert!(matches!(
            p.set("init.plates", ParamValue::Float(1e30)),
            Err(ParamError::OutOfRange { .. })
        ));
    }

    #[test]
    fn negative_integer_rejected() {
        let e = err("[planet]\nseed = -3\n");
        assert!(
            matches!(&e, ParamError::Negative { key, value } if key == "planet.seed" && value == "-3"),
            "{e:?}"
        );
        assert_eq!(
            e.to_string(),
            "parameter \"planet.seed\" must be a non-negative integer, got -3"
        );
        let e = Params::default()
            .set("planet.seed", ParamValue::Float(-2.0))
            .unwrap_err();
        assert!(matches!(e, ParamError::Negative { .. }), "{e:?}");
    }

    #[test]
    fn non_finite_rejected() {
        for (text, shown) in [
            ("nan", "nan"),
            ("inf", "inf"),
            ("-inf", "-inf"),
            ("+inf", "inf"),
        ] {
            let e = err(&format!("[planet]\nradius_km = {text}\n"));
            assert!(
                matches!(&e, ParamError::NonFinite { key, .. } if key == "planet.radius_km"),
                "{e:?}"
            );
            assert_eq!(
                e.to_string(),
                format!("parameter \"planet.radius_km\" = {shown} is not a finite number")
            );
        }
        let e = err("[init]\nplates = nan\n");
        assert!(
            matches!(&e, ParamError::NonFinite { key, .. } if key == "init.plates"),
            "{e:?}"
        );
        let mut p = Params::default();
        assert!(matches!(
            p.set("time.time_step_my", ParamValue::Float(f64::NAN)),
            Err(ParamError::NonFinite { .. })
        ));
        assert_eq!(p, Params::default());
        p.ocean.damping_mm_per_yr = f64::INFINITY;
        assert!(matches!(p.validate(), Err(ParamError::NonFinite { .. })));
    }

    #[test]
    fn out_of_range() {
        let e = err("[init]\nplates = 0\n");
        assert!(
            matches!(&e, ParamError::OutOfRange { key, value: ParamValue::Int(0), .. } if key == "init.plates"),
            "{e:?}"
        );
        assert_eq!(
            e.to_string(),
            "parameter \"init.plates\" = 0 is out of range: allowed 2..=2000"
        );
        let e = err("[planet]\nradius_km = 99.5\n");
        assert_eq!(
            e.to_string(),
            "parameter \"planet.radius_km\" = 99.5 is out of range: allowed 100.0..=100000.0"
        );
    }

    #[test]
    fn range_bounds_are_inclusive_and_exact() {
        // Max seed is accepted (TOML integers are i64, so this is the largest writable).
        let p = Params::from_toml_str("[planet]\nseed = 9223372036854775807\n").unwrap();
        assert_eq!(p.planet.seed, 9_223_372_036_854_775_807);
        let mut p = Params::default();
        // One past the int max is rejected exactly, although it equals the max as f64.
        let e = p
            .set("planet.seed", ParamValue::Int(9_223_372_036_854_775_808))
            .unwrap_err();
        assert!(
            e.to_string().contains("allowed 0..=9223372036854775807"),
            "{e}"
        );
        p.set("planet.sample_jitter", ParamValue::Float(0.9))
            .unwrap();
        p.set("planet.sample_jitter", ParamValue::Float(0.0))
            .unwrap();
        assert!(
            p.set(
                "planet.sample_jitter",
                ParamValue::Float(0.900_000_000_000_000_1)
            )
            .is_err()
        );
        assert!(
            p.set("planet.sample_jitter", ParamValue::Float(-1e-300))
                .is_err()
        );
        p.init.plates = 1;
        assert!(matches!(p.validate(), Err(ParamError::OutOfRange { .. })));
    }

    #[test]
    fn cross_field_plates_vs_samples() {
        let e = err("[planet]\nsamples = 1000\n[init]\nplates = 51\n");
        assert!(
            matches!(
                e,
                ParamError::TooManyPlates {
                    plates: 51,
                    samples: 1000,
                    max_plates: 50
                }
            ),
            "{e:?}"
        );
        let msg = e.to_string();
        assert!(
            msg.contains("init.plates = 51")
                && msg.contains("planet.samples = 1000")
                && msg.contains("every plate needs"),
            "{msg}"
        );
        Params::from_toml_str("[planet]\nsamples = 1000\n[init]\nplates = 50\n").unwrap();
    }

    #[test]
    fn cross_field_ocean_order() {
        let e = err("[ocean]\nabyssal_elevation_km = -0.5\n");
        assert!(matches!(e, ParamError::OceanElevationOrder { .. }), "{e:?}");
        assert!(e.to_string().contains("-10.0 < -0.5 < -1.0 < 0"), "{e}");
        let e = err("[ocean]\nridge_elevation_km = 0\n");
        assert!(matches!(e, ParamError::OceanElevationOrder { .. }), "{e:?}");
        let e = err("[ocean]\ntrench_elevation_km = -6\n");
        assert!(matches!(e, ParamError::OceanElevationOrder { .. }), "{e:?}");
        Params::from_toml_str("[ocean]\ntrench_elevation_km = -6.01\n").unwrap();
    }

    #[test]
    fn cross_field_resample_interval() {
        let e = err("[resample]\nmin_interval_steps = 61\n");
        assert!(
            matches!(e, ParamError::ResampleInterval { min: 61, max: 60 }),
            "{e:?}"
        );
        assert!(
            e.to_string().contains("resample.min_interval_steps = 61"),
            "{e}"
        );
        Params::from_toml_str("[resample]\nmin_interval_steps = 60\n").unwrap();
    }

    #[test]
    fn get_and_set_each_kind() {
        let mut p = Params::default();
        assert_eq!(p.get("planet.radius_km"), Some(ParamValue::Float(6370.0)));
        assert_eq!(p.get("init.plates"), Some(ParamValue::Int(40)));
        assert_eq!(p.get("nope.nope"), None);
        p.set("planet.radius_km", ParamValue::Float(1000.5))
            .unwrap();
        assert_eq!(p.planet.radius_km, 1000.5);
        p.set("planet.radius_km", ParamValue::Int(2000)).unwrap();
        assert_eq!(p.get("planet.radius_km"), Some(ParamValue::Float(2000.0)));
        p.set("init.plates", ParamValue::Int(7)).unwrap();
        assert_eq!(p.init.plates, 7);
        let e = p.set("init.plates", ParamValue::Bool(true)).unwrap_err();
        assert!(
            matches!(
                e,
                ParamError::WrongType {
                    expected: ParamKind::Int,
                    ..
                }
            ),
            "{e:?}"
        );
        assert!(matches!(
            p.set("init.plates", ParamValue::Float(7.5)),
            Err(ParamError::NotIntegral { .. })
        ));
        assert_eq!(p.init.plates, 7);
        // Every schema key is gettable and settable to its default.
        for spec in Params::schema() {
            assert_eq!(
                Params::default().get(spec.key),
                Some(spec.default),
                "{}",
                spec.key
            );
            p.set(spec.key, spec.default).unwrap();
        }
        assert_eq!(p, Params::default());
        // Bool values: display, and a bool for a float field is a type error.
        assert_eq!(ParamValue::Bool(true).to_string(), "true");
        assert!(matches!(
            p.set("time.time_step_my", ParamValue::Bool(false)),
            Err(ParamError::WrongType { .. })
        ));
        let bool_spec = ParamSpec {
            key: "x.flag",
            section: "x",
            name: "flag",
            kind: ParamKind::Bool,
            unit: "",
            doc: "",
            default: ParamValue::Bool(false),
            min: 0.0,
            max: 1.0,
        };
        let bounds = (ParamValue::Bool(false), ParamValue::Bool(true));
        assert_eq!(
            check_value(&bool_spec, bounds, ParamValue::Bool(true)).unwrap(),
            ParamValue::Bool(true)
        );
        assert!(check_value(&bool_spec, bounds, ParamValue::Int(1)).is_err());
    }

    #[test]
    fn schema_is_consistent() {
        let schema = Params::schema();
        assert_eq!(schema.len(), 117);
        assert_eq!(schema.len(), BOUNDS.len());
        let mut seen = HashSet::new();
        for (spec, (lo, hi)) in schema.iter().zip(BOUNDS) {
            assert!(seen.insert(spec.key), "duplicate key {}", spec.key);
            assert_eq!(spec.key, format!("{}.{}", spec.section, spec.name));
            assert!(spec.min <= spec.max, "{}", spec.key);
            assert!(!spec.doc.is_empty(), "{}", spec.key);
            let d = match spec.default {
                ParamValue::Float(x) => x,
                ParamValue::Int(n) => n as f64,
                ParamValue::Bool(b) => f64::from(u8::from(b)),
            };
            assert!(
                spec.min <= d && d <= spec.max,
                "default of {} out of range",
                spec.key
            );
            check_value(spec, (*lo, *hi), spec.default).unwrap();
        }
        assert_eq!(schema[0].key, "planet.radius_km");
        assert_eq!(
            schema[schema.len() - 1].key,
            "resample.fragment_min_area_km2"
        );
        assert_eq!(SECTIONS.len(), 15);
    }

    #[test]
    fn levenshtein_basics() {
        assert_eq!(levenshtein("", ""), 0);
        assert_eq!(levenshtein("abc", ""), 3);
        assert_eq!(levenshtein("kitten", "sitting"), 3);
        assert_eq!(levenshtein("ε_o", "e_o"), 1);
        assert_eq!(suggest_threshold("ab"), 2);
        assert_eq!(suggest_threshold("0123456789abcdef"), 4);
    }

    #[test]
    fn load_errors_name_the_path() {
        let dir = std::env::temp_dir().join(format!("params_test_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let missing = dir.join("missing.toml");
        let e = Params::load(&missing).unwrap_err();
        assert!(matches!(e, ParamError::FileNotFound { .. }), "{e:?}");
        assert!(e.to_string().contains("missing.toml"), "{e}");
        let e = Params::load(&dir).unwrap_err();
        assert!(matches!(e, ParamError::IsDirectory { .. }), "{e:?}");
        assert!(e.to_string().contains(&dir.display().to_string()), "{e}");
        let bad = dir.join("binary.toml");
        std::fs::write(&bad, [0xff_u8, 0xfe, 0x00]).unwrap();
        let e = Params::load(&bad).unwrap_err();
        assert!(matches!(e, ParamError::Unreadable { .. }), "{e:?}");
        assert!(e.to_string().contains("binary.toml"), "{e}");
        let good = dir.join("good.toml");
        std::fs::write(&good, "[rifting]\nfrequency_per_my = 0.5\n").unwrap();
        assert_eq!(Params::load(&good).unwrap().rifting.frequency_per_my, 0.5);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn hostile_inputs_do_not_panic() {
        let long_key = "a".repeat(10_000);
        for text in [
            "\u{0}".to_string(),
            "[[planet]]\nradius_km = 1\n".to_string(),
            "[planet]\nradius_km = 1979-05-27\n".to_string(),
            format!("[ocean]\n{long_key} = 1\n"),
            format!("[{long_key}]\n"),
            "[planet]\nsamples = 99999999999999999999\n".to_string(),
            "[planet]\nsamples = 1e300\n".to_string(),
            "[planet]\nsamples = -0.0\n".to_string(),
        ] {
            let _ = Params::from_toml_str(&text);
        }
        // -0.0 is integral and not negative: it is 0, then out of range.
        assert!(matches!(
            err("[planet]\nsamples = -0.0\n"),
            ParamError::OutOfRange { .. }
        ));
    }

    #[test]
    fn serde_derives_work() {
        let p = Params::default();
        let text = toml::to_string(&p).unwrap();
        let back: Params = toml::from_str(&text).unwrap();
        assert_eq!(back, p);
    }
}
