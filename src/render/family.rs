//! Body families of the carcass randomisation group: broiler, heavy broiler (roaster),
//! spent hen (layer), poussin, long/narrow and round/wide birds. Each is its own
//! generated mesh (`carcass::generate_body` with the family's [`Body`] factors), not the
//! broiler scaled, and carries the broiler's skeleton so every pose and cut applies.
//! Meshes are generated once per process, on first use, and shared.
//!
//! | family | share | size (× today's broiler) | shape |
//! |---|---|---|---|
//! | broiler | 30 % | 0.88–1.12 | the committed asset |
//! | heavy broiler | 15 % | 1.05–1.30 | wide, deep, big breast and thighs |
//! | spent hen | 15 % | 0.80–1.00 | long, narrow, shallow breast, keel shows, thin legs |
//! | poussin | 10 % | 0.70–0.85 | short, rounder, small breast |
//! | long / narrow | 15 % | 0.90–1.15 | long trunk, narrow, longer legs and neck |
//! | round / wide | 15 % | 0.85–1.10 | short trunk, wide, full breast |

use std::sync::{Arc, OnceLock};

use rand::Rng;

use super::asset::Asset;
use super::carcass::{self, Body};

/// One body family.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Family {
    Broiler,
    HeavyBroiler,
    SpentHen,
    Poussin,
    Long,
    Round,
}

impl Family {
    pub const ALL: [Family; 6] = [
        Family::Broiler,
        Family::HeavyBroiler,
        Family::SpentHen,
        Family::Poussin,
        Family::Long,
        Family::Round,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Family::Broiler => "broiler",
            Family::HeavyBroiler => "heavy_broiler",
            Family::SpentHen => "spent_hen",
            Family::Poussin => "poussin",
            Family::Long => "long",
            Family::Round => "round",
        }
    }

    /// Share of carcasses drawn from this family (the table above).
    fn share(self) -> f64 {
        match self {
            Family::Broiler => 0.30,
            Family::HeavyBroiler | Family::SpentHen | Family::Long | Family::Round => 0.15,
            Family::Poussin => 0.10,
        }
    }

    /// Per-instance size range (uniform scale, × today's broiler).
    pub fn size(self) -> [f32; 2] {
        match self {
            Family::Broiler => [0.88, 1.12],
            Family::HeavyBroiler => [1.05, 1.30],
            Family::SpentHen => [0.80, 1.00],
            Family::Poussin => [0.70, 0.85],
            Family::Long => [0.90, 1.15],
            Family::Round => [0.85, 1.10],
        }
    }

    /// The family's shape factors over the broiler.
    pub fn body(self) -> Body {
        let b = Body::BROILER;
        match self {
            Family::Broiler => b,
            Family::HeavyBroiler => Body {
                length: 1.04,
                width: 1.14,
                depth: 1.10,
                breast: 1.25,
                keel: 0.8,
                thigh: 1.15,
                drum: 1.12,
                wing: 0.95,
                ..b
            },
            Family::SpentHen => Body {
                length: 1.06,
                width: 0.84,
                depth: 0.86,
                breast: 0.62,
                keel: 1.7,
                back: 0.9,
                thigh: 0.8,
                drum: 0.78,
                leg: 1.06,
                wing: 1.12,
                neck: 1.25,
                tail: 1.3,
            },
            Family::Poussin => Body {
                length: 0.92,
                width: 0.97,
                depth: 0.95,
                breast: 0.85,
                thigh: 0.92,
                drum: 0.9,
                leg: 0.95,
                wing: 1.05,
                neck: 1.05,
                tail: 0.9,
                ..b
            },
            Family::Long => Body {
                length: 1.16,
                width: 0.9,
                depth: 0.92,
                breast: 0.95,
                keel: 1.1,
                thigh: 0.95,
                drum: 0.95,
                leg: 1.08,
                wing: 1.05,
                neck: 1.1,
                tail: 1.1,
                ..b
            },
            Family::Round => Body {
                length: 0.9,
                width: 1.12,
                depth: 1.06,
                breast: 1.15,
                keel: 0.9,
                thigh: 1.08,
                drum: 1.05,
                leg: 0.92,
                wing: 0.95,
                neck: 0.9,
                tail: 0.95,
                ..b
            },
        }
    }

    /// Draws a family by its share.
    pub fn sample<R: Rng>(rng: &mut R) -> Family {
        let u: f64 = rng.random_range(0.0..1.0);
        let mut acc = 0.0;
        for f in Family::ALL {
            acc += f.share();
            if u < acc {
                return f;
            }
        }
        Family::Round
    }

    /// Generates every family's mesh now (in parallel), e.g. before timing renders.
    pub fn prepare_all() {
        use rayon::prelude::*;
        Family::ALL.par_iter().for_each(|f| {
            f.asset();
        });
    }

    /// The family's mesh, generated on first use and shared by the process; None for
    /// the broiler, whose mesh is the embedded asset the image already has.
    pub fn asset(self) -> Option<Arc<Asset>> {
        static CACHE: [OnceLock<Arc<Asset>>; 6] = [const { OnceLock::new() }; 6];
        let k = Family::ALL.iter().position(|f| *f == self)?;
        if self == Family::Broiler {
            return None;
        }
        Some(
            CACHE[k]
                .get_or_init(|| {
                    let body = self.body();
                    let mesh = carcass::generate_body(&body, carcass::DEFAULT_CELL);
                    Arc::new(Asset::with_spots(mesh, &carcass::red_spots_of(&body)))
                })
                .clone(),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn families_are_valid_and_differ_in_geometry() {
        let shares: f64 = Family::ALL.iter().map(|f| f.share()).sum();
        assert!((shares - 1.0).abs() < 1e-9);
        // Coarse grid keeps the test fast; the shapes are the same SDFs.
        let meshes: Vec<_> = Family::ALL
            .iter()
            .map(|f| {
                f.body().check().unwrap();
                (*f, carcass::generate_body(&f.body(), 0.007))
            })
            .collect();
        let mut stats = Vec::new();
        for (f, m) in &meshes {
            let n = m.positions.len();
            assert!(m.triangle_count() > 500, "{f:?}");
            assert!(m.indices.iter().all(|&i| (i as usize) < n), "{f:?}");
            assert!(
                m.normals
                    .iter()
                    .all(|v| v.is_finite() && (v.length() - 1.0).abs() < 1e-3),
                "{f:?}"
            );
            let s = m.skin.as_ref().unwrap();
            assert_eq!(s.joints.len(), carcass::JOINT_NAMES.len());
            assert!(s
                .vertex_joints
                .iter()
                .flatten()
                .all(|&j| (j as usize) < s.joints.len()));
            let v = m.volume();
            assert!(v > 0.0008 && v < 0.005, "{f:?}: volume {v}");
            let (lo, hi) = m.bounds();
            let e = hi - lo;
            // Extents over length, and fullness (volume over length cubed).
            stats.push((
                *f,
                v,
                glam::Vec4::new(e.y / e.x, e.z / e.x, v / e.x.powi(3), e.x),
            ));
        }
        // Pairwise: each family differs from every other in volume or in some extent
        // by more than 3 % (not a copy, not only a uniform scale of one another).
        // The length itself is not a proportion: a uniform scale changes it.
        for i in 0..stats.len() {
            for j in i + 1..stats.len() {
                let (a, b) = (&stats[i], &stats[j]);
                let rel = (a.2.truncate() - b.2.truncate()).abs() / a.2.truncate();
                let shape = rel.max_element();
                assert!(
                    shape > 0.03,
                    "{:?} and {:?} have the same proportions",
                    a.0,
                    b.0
                );
            }
        }
        let vol = |f: Family| stats.iter().find(|s| s.0 == f).unwrap().1;
        assert!(vol(Family::HeavyBroiler) > vol(Family::Broiler) * 1.15);
        assert!(vol(Family::SpentHen) < vol(Family::Broiler) * 0.9);
    }
}
