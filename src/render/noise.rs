//! Procedural noise (value noise, fBm, cellular) over the stable hashes of `util::hash`, used by the
//! materials, the plate and the sensor. Pure functions of their inputs and a seed, so a
//! pixel's value never depends on which thread shades it (pbrt's hashed sampler idea).

use glam::{IVec3, Vec3};

/// Uniform [0, 1) from a hash.
#[inline]
pub fn unit(h: u64) -> f32 {
    (h >> 40) as f32 / (1u64 << 24) as f32
}

/// One-multiply lattice hash (noise lattices need decorrelation, not crypto quality).
#[inline(always)]
fn lattice_hash(seed: u64, x: i32, y: i32, z: i32) -> u64 {
    let mut h = seed
        ^ (x as u32 as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (y as u32 as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ (z as u32 as u64).wrapping_mul(0x1656_67B1_9E37_79F9);
    h ^= h >> 29;
    h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    h ^ (h >> 32)
}

#[inline(always)]
fn lattice(seed: u64, c: IVec3) -> f32 {
    unit(lattice_hash(seed, c.x, c.y, c.z))
}

/// floor() without the libm call the baseline x86-64 target makes for `f32::floor`.
#[inline(always)]
pub fn ffloor(x: f32) -> f32 {
    let i = x as i32 as f32;
    if i > x {
        i - 1.0
    } else {
        i
    }
}

/// ceil() without the libm call.
#[inline(always)]
pub fn fceil(x: f32) -> f32 {
    -ffloor(-x)
}

#[inline(always)]
fn vfloor(p: Vec3) -> Vec3 {
    Vec3::new(ffloor(p.x), ffloor(p.y), ffloor(p.z))
}

/// Bilinear value noise in [0, 1) (for surfaces that are flat anyway: the plate).
pub fn value2(seed: u64, x: f32, y: f32) -> f32 {
    let (fx, fy) = (ffloor(x), ffloor(y));
    let (ix, iy) = (fx as i32, fy as i32);
    let (tx, ty) = (x - fx, y - fy);
    let (tx, ty) = (tx * tx * (3.0 - 2.0 * tx), ty * ty * (3.0 - 2.0 * ty));
    let l = |dx: i32, dy: i32| unit(lattice_hash(seed, ix + dx, iy + dy, 0));
    let a = l(0, 0) + (l(1, 0) - l(0, 0)) * tx;
    let b = l(0, 1) + (l(1, 1) - l(0, 1)) * tx;
    a + (b - a) * ty
}

/// Fractal sum of 2D value noise, roughly in [0, 1).
pub fn fbm2(seed: u64, x: f32, y: f32, octaves: u32) -> f32 {
    let (mut s, mut a, mut f, mut norm) = (0.0, 1.0, 1.0, 0.0);
    for o in 0..octaves {
        s += a * value2(seed.wrapping_add(o as u64), x * f, y * f);
        norm += a;
        a *= 0.5;
        f *= 2.03;
    }
    s / norm
}

/// Trilinear value noise in [0, 1) with smoothstep fade.
pub fn value3(seed: u64, p: Vec3) -> f32 {
    let f = vfloor(p);
    let c = f.as_ivec3();
    let t = p - f;
    let t = t * t * (Vec3::splat(3.0) - 2.0 * t);
    let l = |dx, dy, dz| lattice(seed, c + IVec3::new(dx, dy, dz));
    let x00 = l(0, 0, 0) + (l(1, 0, 0) - l(0, 0, 0)) * t.x;
    let x10 = l(0, 1, 0) + (l(1, 1, 0) - l(0, 1, 0)) * t.x;
    let x01 = l(0, 0, 1) + (l(1, 0, 1) - l(0, 0, 1)) * t.x;
    let x11 = l(0, 1, 1) + (l(1, 1, 1) - l(0, 1, 1)) * t.x;
    let y0 = x00 + (x10 - x00) * t.y;
    let y1 = x01 + (x11 - x01) * t.y;
    y0 + (y1 - y0) * t.z
}

/// Fractal sum of `octaves` value-noise octaves, roughly in [0, 1).
pub fn fbm3(seed: u64, p: Vec3, octaves: u32) -> f32 {
    let (mut s, mut a, mut f, mut norm) = (0.0, 1.0, 1.0, 0.0);
    for o in 0..octaves {
        s += a * value3(seed.wrapping_add(o as u64), p * f);
        norm += a;
        a *= 0.5;
        f *= 2.03;
    }
    s / norm
}

/// Cellular noise: (distance to the nearest feature point, offset to it), one jittered
/// feature point per unit cell. Searches the 2×2×2 cells nearest to `p` (the octant it
/// lies in) rather than all 27 neighbours: 3× cheaper, and the rare miss only shifts a
/// follicle bump, which nobody can see.
pub fn cellular3(seed: u64, p: Vec3) -> (f32, Vec3) {
    let f = vfloor(p);
    let c = f.as_ivec3();
    let t = p - f;
    let lo = IVec3::new(
        if t.x < 0.5 { -1 } else { 0 },
        if t.y < 0.5 { -1 } else { 0 },
        if t.z < 0.5 { -1 } else { 0 },
    );
    let mut best = (f32::INFINITY, Vec3::ZERO);
    for dz in 0..2 {
        for dy in 0..2 {
            for dx in 0..2 {
                let cc = c + lo + IVec3::new(dx, dy, dz);
                let h = lattice_hash(seed, cc.x, cc.y, cc.z);
                let j = Vec3::new(unit(h), unit(h << 21), unit(h << 42));
                let d = cc.as_vec3() + j - p;
                let l = d.length_squared();
                if l < best.0 {
                    best = (l, d);
                }
            }
        }
    }
    (best.0.sqrt(), best.1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_bounded_continuous_and_seeded() {
        let mut prev = value3(1, Vec3::new(0.0, 0.3, -0.7));
        for i in 1..500 {
            let p = Vec3::new(i as f32 * 0.01, 0.3, -0.7);
            let v = value3(1, p);
            assert!((0.0..1.0).contains(&v));
            assert!((v - prev).abs() < 0.1);
            prev = v;
        }
        assert_ne!(value3(1, Vec3::splat(0.5)), value3(2, Vec3::splat(0.5)));
        let (d, off) = cellular3(7, Vec3::new(0.2, 5.1, -3.3));
        assert!(d <= 3f32.sqrt() && (off.length() - d).abs() < 1e-5);
    }
}
