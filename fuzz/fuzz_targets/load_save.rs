//! Fuzzes the save loader: any bytes must give a simulation or a clear error, never a panic, a
//! hang or an allocation sized by an unchecked length.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use tectonic_planets::io::save;

fuzz_target!(|data: &[u8]| {
    // As given: exercises the header and checksum checks.
    let _ = save::load_from_bytes(data, Path::new("fuzz.planet"));
    // With a valid header (magic, version, body length, checksum) so that the bytes reach the
    // section table and the section readers.
    if data.len() >= save::HEADER_LEN {
        let mut b = data.to_vec();
        b[..8].copy_from_slice(&save::MAGIC);
        b[8..12].copy_from_slice(&save::FORMAT_VERSION.to_le_bytes());
        let body = (b.len() - save::HEADER_LEN) as u64;
        b[16..24].copy_from_slice(&body.to_le_bytes());
        let crc = save::checksum(&b);
        b[24..28].copy_from_slice(&crc.to_le_bytes());
        if let Ok(mut sim) = save::load_from_bytes(&b, Path::new("fuzz.planet")) {
            // Whatever loads must be able to step.
            let _ = sim.step();
        }
    }
});
