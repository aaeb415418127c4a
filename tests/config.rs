//! Bad configurations: every malformed or out-of-range parameter file gets a clear error naming
//! the key and the problem (never a panic or a hang), checked through the library.

use tectonic_planets::prelude::*;

/// Parses `text`, expects an error whose message holds every needle.
fn refused(text: &str, needles: &[&str]) {
    let e = Params::from_toml_str(text)
        .err()
        .unwrap_or_else(|| panic!("{text:?} should be refused"));
    let msg = e.to_string();
    for n in needles {
        assert!(msg.contains(n), "{text:?}: message {msg:?} lacks {n:?}");
    }
}

#[test]
fn malformed_and_unknown_keys() {
    refused("[planet\nseed = 1\n", &["TOML"]);
    refused("[planet]\nseed = \n", &["TOML"]);
    refused("[planet]\nseeed = 3\n", &["seeed", "planet.seed"]);
    refused("[oceen]\nridge_elevation_km = -1.0\n", &["oceen", "ocean"]);
    refused("planet = 3\n", &["planet", "table"]);
    refused("[planet]\nseed = \"one\"\n", &["planet.seed"]);
}

#[test]
fn non_finite_and_negative_values() {
    refused("[planet]\nradius_km = nan\n", &["planet.radius_km", "nan"]);
    refused("[planet]\nradius_km = -inf\n", &["planet.radius_km", "inf"]);
    refused(
        "[plates]\nmax_speed_mm_per_yr = inf\n",
        &["plates.max_speed_mm_per_yr"],
    );
    refused("[planet]\nsamples = -5\n", &["planet.samples", "-5"]);
    refused("[init]\nplates = -1\n", &["init.plates", "-1"]);
    refused("[planet]\nsamples = 1e30\n", &["planet.samples"]);
    refused(
        "[planet]\nradius_km = -6370.0\n",
        &["planet.radius_km", "-6370"],
    );
}

#[test]
fn plate_counts() {
    refused("[init]\nplates = 0\n", &["init.plates", "0"]);
    refused(
        "[planet]\nsamples = 1000\n[init]\nplates = 1000\n",
        &["init.plates", "planet.samples"],
    );
    refused(
        "[planet]\nsamples = 2000\n[init]\nplates = 5000\n",
        &["init.plates"],
    );
    // The most plates allowed for the sample count still builds a valid planet (and does not
    // hang).
    let p = Params::from_toml_str("[planet]\nsamples = 1000\n[init]\nplates = 50\n").unwrap();
    let mut sim = Simulation::new(p).unwrap();
    sim.run_steps(3).unwrap();
    assert!(sim.stats().plates >= 2);
}
