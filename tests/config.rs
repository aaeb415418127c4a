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

/// docs/parameters.md states each parameter's default in two tables (the model's constants with
/// their sources, and every key with its meaning): each stated default is the code's. The first
/// table once gave the paper's values as defaults where the code had moved on (r_s 1800 against
/// 900 km, u_0 0.6 against 0.9 mm/yr, and four more).
#[test]
fn the_parameter_tables_state_the_code_defaults() {
    use tectonic_planets::resources::params::ParamValue;
    let doc = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/parameters.md"))
        .expect("docs/parameters.md");
    let defaults = Params::default();
    // The leading number (or true/false) of a table cell: "900 km" → 900, "1.3e−5 /km" → 1.3e-5.
    let leading = |cell: &str| -> Option<f64> {
        let cell = cell.trim().replace('−', "-");
        match cell.split_whitespace().next()? {
            "true" => return Some(1.0),
            "false" => return Some(0.0),
            _ => {}
        }
        let num: String = cell
            .chars()
            .take_while(|c| c.is_ascii_digit() || matches!(c, '.' | '-' | 'e' | ','))
            .collect();
        let mantissa: f64 = num.replace(',', "").parse().ok()?;
        // "6·10⁶": a power of ten in superscript digits.
        let Some(power) = cell[num.len()..].strip_prefix("·10") else {
            return Some(mantissa);
        };
        let sup = "⁰¹²³⁴⁵⁶⁷⁸⁹";
        let mut exp = 0i32;
        for c in power.chars() {
            match sup.chars().position(|d| d == c) {
                Some(d) => exp = exp * 10 + d as i32,
                None => break,
            }
        }
        Some(mantissa * 10f64.powi(exp))
    };
    let (mut checked, mut wrong) = (0, Vec::new());
    for line in doc.lines().filter(|l| l.starts_with('|')) {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        // The key is the first cell that is one backticked key; the default is the next cell.
        let Some(k) = cells.iter().position(|c| {
            c.starts_with('`')
                && c.ends_with('`')
                && c.len() > 2
                && !c[1..c.len() - 1].contains('`')
        }) else {
            continue;
        };
        let key = &cells[k][1..cells[k].len() - 1];
        let Some(value) = defaults.get(key) else {
            continue;
        };
        let Some(stated) = cells.get(k + 1).and_then(|c| leading(c)) else {
            continue;
        };
        let code = match value {
            ParamValue::Float(v) => v,
            ParamValue::Int(v) => v as f64,
            ParamValue::Bool(b) => f64::from(u8::from(b)),
        };
        checked += 1;
        if (stated - code).abs() > 1e-9 * code.abs().max(1.0) {
            wrong.push(format!("{key}: the docs say {stated}, the code {code}"));
        }
    }
    assert!(checked > 60, "only {checked} stated defaults found");
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}
