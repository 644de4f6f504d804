//! Closed triangle-mesh primitives (boxes, capsules, ellipsoids) for the bed, the robot arm and the test mannequin.
//!
//! Meshes are appended into a [`TriMesh`] so a whole object (bed, arm) is one draw call. Building costs O(vertices);
//! these are built once per scene or per frame (a few hundred triangles each).

use nalgebra::{Isometry3, Point3, Vector3};

/// An indexed triangle mesh in some frame (metres).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions.
    pub vertices: Vec<[f32; 3]>,
    /// Triangles as vertex indices, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
}

impl TriMesh {
    /// Remove everything, keeping capacity.
    pub fn clear(&mut self) {
        self.vertices.clear();
        self.triangles.clear();
    }

    /// Append a box with half extents `half`, placed by `pose` (box frame → mesh frame).
    pub fn add_box(&mut self, pose: &Isometry3<f32>, half: [f32; 3]) {
        let base = self.vertices.len() as u32;
        for i in 0..8 {
            let s = |bit: u32, h: f32| if i & (1 << bit) != 0 { h } else { -h };
            let p = pose * Point3::new(s(0, half[0]), s(1, half[1]), s(2, half[2]));
            self.vertices.push([p.x, p.y, p.z]);
        }
        // Faces as quads of corner indices (bit0 = +x, bit1 = +y, bit2 = +z), outward counter-clockwise.
        const QUADS: [[u32; 4]; 6] = [
            [0, 2, 3, 1],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
        ];
        for q in QUADS {
            self.triangles.push([base + q[0], base + q[1], base + q[2]]);
            self.triangles.push([base + q[0], base + q[2], base + q[3]]);
        }
    }

    /// Append an axis-aligned box spanning `lo`..`hi`.
    pub fn add_aabb(&mut self, lo: [f32; 3], hi: [f32; 3]) {
        let c = Vector3::new(
            (lo[0] + hi[0]) * 0.5,
            (lo[1] + hi[1]) * 0.5,
            (lo[2] + hi[2]) * 0.5,
        );
        let half = [
            (hi[0] - lo[0]) * 0.5,
            (hi[1] - lo[1]) * 0.5,
            (hi[2] - lo[2]) * 0.5,
        ];
        self.add_box(&Isometry3::translation(c.x, c.y, c.z), half);
    }

    /// Append an ellipsoid with semi-axes `radii` placed by `pose`, tessellated with `rings` x `segments`.
    pub fn add_ellipsoid(&mut self, pose: &Isometry3<f32>, radii: [f32; 3], rings: u32, segments: u32) {
        let base = self.vertices.len() as u32;
        for r in 0..=rings {
            let phi = std::f32::consts::PI * r as f32 / rings as f32; // 0 at +z pole
            for s in 0..segments {
                let th = std::f32::consts::TAU * s as f32 / segments as f32;
                let p = Point3::new(
                    radii[0] * phi.sin() * th.cos(),
                    radii[1] * phi.sin() * th.sin(),
                    radii[2] * phi.cos(),
                );
                let p = pose * p;
                self.vertices.push([p.x, p.y, p.z]);
            }
        }
        for r in 0..rings {
            for s in 0..segments {
                let a = base + r * segments + s;
                let b = base + r * segments + (s + 1) % segments;
                let c = a + segments;
                let d = b + segments;
                if r > 0 {
                    self.triangles.push([a, c, b]);
                }
                if r + 1 < rings {
                    self.triangles.push([b, c, d]);
                }
            }
        }
    }

    /// Append a capsule of radius `radius` from `a` to `b` (a cylinder with hemispherical caps).
    pub fn add_capsule(&mut self, a: [f32; 3], b: [f32; 3], radius: f32, segments: u32) {
        let (pa, pb) = (Vector3::from(a), Vector3::from(b));
        let axis = pb - pa;
        let len = axis.norm().max(1e-6);
        let dir = axis / len;
        // An orthonormal frame with z along the capsule.
        let helper = if dir.z.abs() < 0.9 {
            Vector3::z()
        } else {
            Vector3::x()
        };
        let x = helper.cross(&dir).normalize();
        let y = dir.cross(&x);
        let base = self.vertices.len() as u32;
        let half_rings = (segments / 4).max(2);
        // Rings from the `a` pole (bottom cap) through the cylinder to the `b` pole.
        let mut ring_count = 0u32;
        for (centre, from, to) in [(pa, 0, half_rings), (pb, half_rings, 2 * half_rings)] {
            for r in from..=to {
                let phi = std::f32::consts::PI * r as f32 / (2 * half_rings) as f32; // 0 at the `a` pole
                let along = -phi.cos() * radius;
                let rad = phi.sin() * radius;
                for s in 0..segments {
                    let th = std::f32::consts::TAU * s as f32 / segments as f32;
                    let p = centre + dir * along + (x * th.cos() + y * th.sin()) * rad;
                    self.vertices.push([p.x, p.y, p.z]);
                }
                ring_count += 1;
            }
        }
        for r in 0..ring_count - 1 {
            for s in 0..segments {
                let a = base + r * segments + s;
                let b = base + r * segments + (s + 1) % segments;
                let c = a + segments;
                let d = b + segments;
                self.triangles.push([a, b, c]);
                self.triangles.push([b, d, c]);
            }
        }
    }

    /// Append `other` transformed by `pose`.
    pub fn append(&mut self, other: &TriMesh, pose: &Isometry3<f32>) {
        let base = self.vertices.len() as u32;
        self.vertices.extend(other.vertices.iter().map(|v| {
            let p = pose * Point3::from(*v);
            [p.x, p.y, p.z]
        }));
        self.triangles.extend(
            other
                .triangles
                .iter()
                .map(|t| [t[0] + base, t[1] + base, t[2] + base]),
        );
    }
}

/// Area-weighted unit vertex normals of `triangles` over `vertices` (zero-length where a vertex has no triangle).
pub fn vertex_normals(vertices: &[[f32; 3]], triangles: &[[u32; 3]]) -> Vec<[f32; 3]> {
    let mut acc = vec![Vector3::<f32>::zeros(); vertices.len()];
    for t in triangles {
        let [a, b, c] = t.map(|i| Vector3::from(vertices[i as usize]));
        let n = (b - a).cross(&(c - a));
        for &i in t {
            acc[i as usize] += n;
        }
    }
    acc.into_iter()
        .map(|n| {
            let l = n.norm();
            if l > 0.0 {
                [n.x / l, n.y / l, n.z / l]
            } else {
                [0.0; 3]
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Signed volume by the divergence theorem: positive for closed, outward-oriented meshes.
    fn volume(m: &TriMesh) -> f32 {
        m.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| Vector3::from(m.vertices[i as usize]));
                a.dot(&b.cross(&c)) / 6.0
            })
            .sum()
    }

    #[test]
    fn primitives_are_closed_and_outward() {
        let mut m = TriMesh::default();
        m.add_aabb([0.0, 0.0, 0.0], [1.0, 2.0, 3.0]);
        assert!((volume(&m) - 6.0).abs() < 1e-4);
        let mut e = TriMesh::default();
        e.add_ellipsoid(&Isometry3::identity(), [1.0, 1.0, 1.0], 24, 48);
        let v = volume(&e);
        assert!((v - 4.18879).abs() < 0.05, "sphere volume {v}");
        let mut c = TriMesh::default();
        c.add_capsule([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 0.1, 32);
        let expected = std::f32::consts::PI * 0.01 * 1.0 + 4.0 / 3.0 * std::f32::consts::PI * 0.001;
        let v = volume(&c);
        assert!(
            (v - expected).abs() < 0.03 * expected,
            "capsule volume {v} vs {expected}"
        );
    }
}
