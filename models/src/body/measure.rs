//! Anthropometric measurements of a rest-pose body mesh, for calibrating the population.
//!
//! - height: z extent of the skin vertices (soles to crown), as anny's `Anthropometry.height`;
//! - mass: enclosed volume of the watertight skin × [`BODY_DENSITY`] (divergence theorem over the triangles);
//! - waist: perimeter of the closed vertex loop [`WAIST_LOOP`] around the navel level (anny `anthropometry.py`,
//!   Apache-2.0); MakeHuman's "weight" is not BMI, so BMI is derived from mass and height.

/// Body density in kg/m³ (whole-body average with normal lung volume; the reference notes use ~985).
pub const BODY_DENSITY: f64 = 985.0;

/// Waist loop of the hm08 mesh (anny `BASE_MESH_WAIST_VERTICES`, Apache-2.0), in loop order.
pub const WAIST_LOOP: [u32; 46] = [
    4121, 10763, 10760, 10757, 10777, 10776, 10779, 10780, 10778, 10781, 10771, 10773, 10772, 10775, 10774,
    10814, 10834, 10816, 10817, 10818, 10819, 10820, 10821, 4181, 4180, 4179, 4178, 4177, 4176, 4175, 4196,
    4173, 4131, 4132, 4129, 4130, 4128, 4138, 4135, 4137, 4136, 4133, 4134, 4108, 4113, 4118,
];

/// Measurements of one body.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Measurements {
    /// Standing height, metres.
    pub height_m: f64,
    /// Enclosed skin volume, m³.
    pub volume_m3: f64,
    /// Mass, kg.
    pub mass_kg: f64,
    /// Body-mass index, kg/m².
    pub bmi: f64,
    /// Waist circumference, metres.
    pub waist_m: f64,
}

/// Signed enclosed volume of a closed triangle mesh (positive when triangles are counter-clockwise seen from
/// outside).
pub fn volume(vertices: &[[f64; 3]], triangles: &[[u32; 3]]) -> f64 {
    let mut six_v = 0.0;
    for t in triangles {
        let a = vertices[t[0] as usize];
        let b = vertices[t[1] as usize];
        let c = vertices[t[2] as usize];
        // a · (b × c)
        six_v += a[0] * (b[1] * c[2] - b[2] * c[1])
            + a[1] * (b[2] * c[0] - b[0] * c[2])
            + a[2] * (b[0] * c[1] - b[1] * c[0]);
    }
    six_v / 6.0
}

/// Measure a body: `vertices` must hold at least the skin vertices; `triangles` are the skin triangles.
pub fn measure(vertices: &[[f64; 3]], skin_vertices: usize, triangles: &[[u32; 3]]) -> Measurements {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in &vertices[..skin_vertices] {
        lo = lo.min(v[2]);
        hi = hi.max(v[2]);
    }
    let height_m = hi - lo;
    let volume_m3 = volume(vertices, triangles);
    let mass_kg = volume_m3 * BODY_DENSITY;
    let mut waist_m = 0.0;
    for i in 0..WAIST_LOOP.len() {
        let a = vertices[WAIST_LOOP[i] as usize];
        let b = vertices[WAIST_LOOP[(i + 1) % WAIST_LOOP.len()] as usize];
        waist_m += ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
    }
    Measurements {
        height_m,
        volume_m3,
        mass_kg,
        bmi: mass_kg / (height_m * height_m),
        waist_m,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_cube_volume_and_orientation() {
        let v: Vec<[f64; 3]> = (0..8)
            .map(|i| [(i & 1) as f64, ((i >> 1) & 1) as f64, ((i >> 2) & 1) as f64])
            .collect();
        // Outward counter-clockwise faces of the unit cube.
        let quads = [
            [0, 2, 3, 1],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
        ];
        let tris: Vec<[u32; 3]> = quads
            .iter()
            .flat_map(|q: &[u32; 4]| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
            .collect();
        assert!((volume(&v, &tris) - 1.0).abs() < 1e-12);
        let flipped: Vec<[u32; 3]> = tris.iter().map(|t| [t[0], t[2], t[1]]).collect();
        assert!((volume(&v, &flipped) + 1.0).abs() < 1e-12);
    }
}
