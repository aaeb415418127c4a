//! Small spherical-geometry helpers on the unit sphere (distances, tangent frames, triangle areas,
//! lat/lon conversion). Angles are radians unless a name says otherwise.

use glam::DVec3;

/// Great-circle angle between two unit vectors, robust near 0 and π (atan2 form, no acos).
#[inline]
pub fn angle_between(a: DVec3, b: DVec3) -> f64 {
    a.cross(b).length().atan2(a.dot(b))
}

/// Triple product `a · (b × c)`: positive when (a, b, c) is counter-clockwise seen from outside.
#[inline]
pub fn triple(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    a.dot(b.cross(c))
}

/// Area (spherical excess, steradians) of the spherical triangle (a, b, c), via
/// Van Oosterom–Strackee: tan(E/2) = |a·(b×c)| / (1 + a·b + b·c + c·a).
#[inline]
pub fn spherical_triangle_area(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let num = triple(a, b, c).abs();
    let den = 1.0 + a.dot(b) + b.dot(c) + c.dot(a);
    2.0 * num.atan2(den)
}

/// Projects `v` onto the tangent plane of the unit sphere at `p`.
#[inline]
pub fn tangent_component(p: DVec3, v: DVec3) -> DVec3 {
    v - p * p.dot(v)
}

/// Two unit vectors (east-like, north-like) spanning the tangent plane at unit vector `p`.
pub fn tangent_basis(p: DVec3) -> (DVec3, DVec3) {
    let helper = if p.z.abs() < 0.9 { DVec3::Z } else { DVec3::X };
    let e1 = helper.cross(p).normalize();
    let e2 = p.cross(e1);
    (e1, e2)
}

/// Unit vector for latitude/longitude in degrees (+z is the north pole, longitude grows from +x
/// toward +y).
pub fn from_lat_lon_deg(lat_deg: f64, lon_deg: f64) -> DVec3 {
    let (lat, lon) = (lat_deg.to_radians(), lon_deg.to_radians());
    DVec3::new(lat.cos() * lon.cos(), lat.cos() * lon.sin(), lat.sin())
}

/// Latitude and longitude in degrees of a unit vector (inverse of [`from_lat_lon_deg`]).
pub fn to_lat_lon_deg(p: DVec3) -> (f64, f64) {
    let lat = p.z.clamp(-1.0, 1.0).asin().to_degrees();
    let lon = p.y.atan2(p.x).to_degrees();
    (lat, lon)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn octant_triangle_has_area_half_pi() {
        let a = spherical_triangle_area(DVec3::X, DVec3::Y, DVec3::Z);
        assert!((a - std::f64::consts::FRAC_PI_2).abs() < 1e-12, "{a}");
    }

    #[test]
    fn angle_is_accurate_for_tiny_and_opposite_vectors() {
        let a = DVec3::X;
        let b = DVec3::new(1.0, 1e-9, 0.0).normalize();
        assert!((angle_between(a, b) - 1e-9).abs() < 1e-18);
        assert!((angle_between(a, -a) - std::f64::consts::PI).abs() < 1e-12);
    }

    #[test]
    fn lat_lon_round_trip() {
        for &(lat, lon) in &[(0.0, 0.0), (45.0, 90.0), (-30.0, -120.0), (89.0, 179.0)] {
            let (la, lo) = to_lat_lon_deg(from_lat_lon_deg(lat, lon));
            assert!((la - lat).abs() < 1e-9 && (lo - lon).abs() < 1e-9);
        }
    }
}
