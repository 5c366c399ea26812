"""Second cross-domain validation set for chicktrain (issue 38 part 0): Mitsuba 3.

Renders piles of plucked chicken carcasses with Mitsuba 3's CPU `scalar_rgb` path
tracer (not Blender, not chicktrain's tracer) and writes COCO instance masks of the
visible parts, read from the renderer's own `shape_index` AOV (one sample at each pixel
centre, no filter), so every label is exact. Differs from `bench/crossdomain/` in
renderer, carcass geometry (signed-distance blobs, marching cubes, per-vertex skin
colour; no Blender primitives, no voxel remesh), piling (height-field drop, no rigid-body
physics), surfaces (wet stainless trays with rims, plastic crates, grey / green belts),
light colour, and camera height and tilt (up to 28 degrees). See README.md.

Usage (from the repository root, in a venv with requirements.txt):
    python bench/crossdomain2/make_crossdomain2.py --out DIR --count 100 --size 256 --seed 0 --spp 16

Image k depends only on (seed, k, size, spp): numpy.random.default_rng([seed, k])
draws everything, Mitsuba's sampler seed included, and one render thread. Resumable:
images whose JPEG and sidecar exist are skipped; annotations.json is written from the
sidecars at the end.
"""

import argparse
import json
import os
import sys
import tempfile
import time

import drjit as dr
import mitsuba as mi
import numpy as np
from PIL import Image
from pycocotools import mask as mask_utils
from skimage.measure import marching_cubes

mi.set_variant("scalar_rgb")

MIN_VISIBLE_PX = 100


# ---------------------------------------------------------------- carcass geometry
def ellipsoid(p, c, r):
    """Approximate signed distance to an axis-aligned ellipsoid (centre c, radii r)."""
    q = (p - c) / r
    k0 = np.linalg.norm(q, axis=-1)
    return (k0 - 1.0) * np.min(r)


def capsule(p, a, b, ra, rb):
    """Signed distance to a tapered capsule from a (radius ra) to b (radius rb)."""
    ab = b - a
    t = np.clip(((p - a) @ ab) / (ab @ ab), 0.0, 1.0)
    closest = a + t[..., None] * ab
    return np.linalg.norm(p - closest, axis=-1) - (ra + (rb - ra) * t)


def smin(a, b, k):
    """Polynomial smooth minimum (a smooth union of two distance fields)."""
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b * (1 - h) + a * h - k * h * (1 - h)


def carcass_sdf(rng):
    """A random carcass as a list of (sdf function, part name) in its local frame:
    body axis x (neck at +x), breast up (+z). Returns (field(p), half extent)."""
    L = rng.uniform(0.17, 0.26)  # body length (m)
    W = L * rng.uniform(0.55, 0.72)
    D = L * rng.uniform(0.42, 0.55)
    parts = [lambda p: ellipsoid(p, np.array([0, 0, 0.0]), np.array([L / 2, W / 2, D / 2]))]
    bh = rng.uniform(0.15, 0.35)
    for s in (-1, 1):
        parts.append(lambda p, s=s: ellipsoid(
            p, np.array([0.05 * L, s * 0.16 * W, bh * D]), np.array([0.30 * L, 0.24 * W, 0.30 * D])))
    legs = [s for s in (-1, 1) if rng.random() > 0.12]
    spread = rng.uniform(0.15, 0.45)
    lift = rng.uniform(0.0, 0.35)
    for s in legs:
        parts.append(lambda p, s=s: ellipsoid(
            p, np.array([-0.18 * L, s * 0.42 * W, -0.02 * D]), np.array([0.2 * L, 0.17 * W, 0.24 * D])))
        if rng.random() > 0.08:
            a = np.array([-0.25 * L, s * 0.45 * W, 0.05 * D])
            b = np.array([-0.62 * L, s * spread * W, lift * D])
            parts.append(lambda p, a=a, b=b: capsule(p, a, b, 0.075 * L, 0.04 * L))
            parts.append(lambda p, b=b: ellipsoid(p, b, np.array([0.05, 0.04, 0.04]) * L))
    opened = rng.random() < 0.3
    for s in (-1, 1):
        if rng.random() < 0.15:
            continue
        sh = np.array([0.28 * L, s * 0.46 * W, 0.0])
        el = np.array([0.05 * L, s * (0.62 if not opened else 0.85) * W, -0.12 * D])
        tip = np.array([(0.3 if not opened else 0.1) * L, s * (0.62 if not opened else 1.05) * W, -0.22 * D])
        parts.append(lambda p, a=sh, b=el: capsule(p, a, b, 0.06 * L, 0.045 * L))
        parts.append(lambda p, a=el, b=tip: capsule(p, a, b, 0.04 * L, 0.022 * L))
    if rng.random() < 0.8:
        neck_a = np.array([0.42 * L, 0.0, 0.05 * D])
        neck_b = np.array([rng.uniform(0.52, 0.62) * L, 0.0, rng.uniform(-0.05, 0.15) * D])
        parts.append(lambda p: capsule(p, neck_a, neck_b, 0.085 * L, 0.07 * L))
    parts.append(lambda p: ellipsoid(p, np.array([-0.5 * L, 0, -0.08 * D]), np.array([0.07, 0.06, 0.05]) * L))
    waves = [(rng.normal(size=3) * rng.uniform(25, 60), rng.uniform(0, 6.3)) for _ in range(6)]
    amp = rng.uniform(0.001, 0.003)

    def field(p):
        d = parts[0](p)
        for f in parts[1:]:
            d = smin(d, f(p), 0.018 * L / 0.2)
        for k, ph in waves:
            d = d + amp * np.sin(p @ k + ph)
        return d

    return field, 0.75 * L + 0.1 * W


def carcass_mesh(rng):
    """Marching-cubes mesh of a random carcass: vertices (m), faces, normals, colours."""
    field, half = carcass_sdf(rng)
    n = 40
    g = np.linspace(-half, half, n)
    P = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1)
    sdf = field(P)
    v, f, _, _ = marching_cubes(sdf, 0.0, spacing=(g[1] - g[0],) * 3)
    v = v - half
    # Outward winding: flip if the signed volume is negative.
    vol = np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])).sum()
    if vol < 0:
        f = f[:, ::-1]
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    vn = np.zeros_like(v)
    for i in range(3):
        np.add.at(vn, f[:, i], fn)
    vn /= np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-12)
    # Skin: a base between pale pink and yellow, a low-frequency mottling, redder
    # extremities (far from the body centre), and a few red patches.
    pink = np.array([0.86, 0.63, 0.56])
    yellow = np.array([0.90, 0.74, 0.50])
    base = pink + (yellow - pink) * rng.uniform(0, 1)
    base *= rng.uniform(0.85, 1.05)
    k = rng.normal(size=(3, 3)) * 30
    mott = np.sin(v @ k[0] + rng.uniform(0, 6)) * np.sin(v @ k[1]) * 0.06
    r = np.linalg.norm(v / np.array([1.0, 1.3, 1.3]), axis=1) / half
    red = np.clip((r - 0.55) * 2.5, 0, 1) * rng.uniform(0.2, 0.6)
    for _ in range(rng.integers(0, 4)):
        c = v[rng.integers(len(v))]
        red += np.exp(-np.sum((v - c) ** 2, axis=1) / (2 * rng.uniform(0.01, 0.025) ** 2)) * rng.uniform(0.3, 0.7)
    red = np.clip(red, 0, 1)[:, None]
    col = np.clip(base * (1 + mott[:, None]), 0, 1)
    col = col * (1 - red) + np.array([0.78, 0.32, 0.30]) * red
    col = np.clip(col, 0, 1) ** 2.2  # sRGB-ish to linear
    return v.astype(np.float32), f.astype(np.uint32), vn.astype(np.float32), col.astype(np.float32)


def random_rotation(rng):
    """Mostly breast up or down, some on a side, any yaw."""
    mode = rng.choice(3, p=[0.5, 0.3, 0.2])
    roll = {0: 0.0, 1: np.pi, 2: rng.choice([-1, 1]) * np.pi / 2}[mode] + rng.normal(0, 0.18)
    pitch = rng.normal(0, 0.15)
    yaw = rng.uniform(0, 2 * np.pi)

    def rx(a):
        return np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])

    def ry(a):
        return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])

    def rz(a):
        return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])

    return rz(yaw) @ ry(pitch) @ rx(roll)


class HeightField:
    """Max height on a 1 cm grid: each carcass drops straight down onto what lies there."""

    def __init__(self, half, floor):
        self.res = 0.01
        self.half = half
        n = int(2 * half / self.res) + 1
        self.h = np.full((n, n), floor)

    def cells(self, xy):
        ij = np.round((xy + self.half) / self.res).astype(int)
        return np.clip(ij, 0, self.h.shape[0] - 1)

    def drop(self, v):
        ij = self.cells(v[:, :2])
        under = self.h[ij[:, 0], ij[:, 1]]
        # Sink 15 % of a contact into soft neighbours: carcasses press into each other.
        lift = np.max(under - v[:, 2])
        return lift - 0.004

    def add(self, v):
        ij = self.cells(v[:, :2])
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                i = np.clip(ij[:, 0] + di, 0, self.h.shape[0] - 1)
                j = np.clip(ij[:, 1] + dj, 0, self.h.shape[1] - 1)
                np.maximum.at(self.h, (i, j), v[:, 2])


# ---------------------------------------------------------------- scene
def kelvin_rgb(k):
    """Approximate linear RGB of a black body at k kelvin (Tanner Helland's fit), max 1."""
    t = k / 100.0
    r = 255.0 if t <= 66 else 329.7 * (t - 60) ** -0.1332
    g = 99.47 * np.log(t) - 161.12 if t <= 66 else 288.12 * (t - 60) ** -0.0755
    b = 255.0 if t >= 66 else (0.0 if t <= 19 else 138.52 * np.log(t - 10) - 305.04)
    c = np.clip(np.array([r, g, b]) / 255.0, 0, 1) ** 2.2
    return c / c.max()


def belt_texture(rng, path, kind):
    """A belt or crate-floor texture as PNG: slats / modular links with grime."""
    n = 256
    y, x = np.mgrid[0:n, 0:n] / n
    if kind == "green":
        base = np.array([0.16, 0.42, 0.27]) * rng.uniform(0.7, 1.1)
    elif kind == "grey":
        base = np.array([0.45, 0.46, 0.47]) * rng.uniform(0.6, 1.2)
    else:  # crate plastic
        base = [np.array([0.20, 0.33, 0.62]), np.array([0.62, 0.14, 0.12]), np.array([0.75, 0.75, 0.72])][rng.integers(3)]
    period = rng.uniform(8, 20)
    slat = 0.78 + 0.22 * (np.abs(np.sin(np.pi * y * period)) > 0.12)
    if kind == "crate":
        slat = slat * (0.8 + 0.2 * (np.abs(np.sin(np.pi * x * period * 0.5)) > 0.3))
    grime = 1 + 0.08 * np.sin(x * rng.uniform(5, 15) + rng.uniform(0, 6)) * np.sin(y * rng.uniform(5, 15))
    img = np.clip(base[None, None, :] * (slat * grime)[..., None], 0, 1)
    Image.fromarray((img * 255).astype(np.uint8)).save(path)


def surface(rng, tmp, k):
    """The surface under the pile: (name, dict of Mitsuba shapes, half extent of the pile area)."""
    kind = rng.choice(["tray", "crate", "belt_grey", "belt_green"], p=[0.35, 0.25, 0.2, 0.2])
    shapes = {}
    big = mi.ScalarTransform4f().scale([3.0, 3.0, 1.0])
    if kind == "tray":
        wet = rng.random() < 0.7
        alpha = rng.uniform(0.03, 0.08) if wet else rng.uniform(0.12, 0.3)
        steel = {"type": "roughconductor", "material": "Cr", "alpha": float(alpha)}
        if wet:
            steel = {"type": "roughplastic", "diffuse_reflectance": {"type": "rgb", "value": [0.05, 0.05, 0.055]},
                     "alpha": 0.02, "int_ior": 1.33, "nonlinear": True}
            steel = {"type": "blendbsdf", "weight": float(rng.uniform(0.3, 0.6)), "bsdf_0": {"type": "roughconductor", "material": "Cr", "alpha": float(alpha)}, "bsdf_1": steel}
        half = rng.uniform(0.28, 0.4)
        shapes["floor"] = {"type": "rectangle", "to_world": big, "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(rng.uniform(0.05, 0.25, 3))}}}
        shapes["tray"] = {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([0, 0, 0.001]).scale([half + 0.05, half + 0.05, 1]), "bsdf": steel}
        for i, (tx, ty, sx, sy) in enumerate([(half + 0.05, 0, 0.01, half + 0.06), (-half - 0.05, 0, 0.01, half + 0.06),
                                              (0, half + 0.05, half + 0.06, 0.01), (0, -half - 0.05, half + 0.06, 0.01)]):
            shapes[f"rim{i}"] = {"type": "cube", "to_world": mi.ScalarTransform4f().translate([tx, ty, 0.02]).scale([sx, sy, 0.02]),
                                 "bsdf": {"type": "roughconductor", "material": "Cr", "alpha": 0.2}}
        return kind, shapes, half
    if kind == "crate":
        half = rng.uniform(0.22, 0.3)
        tex = os.path.join(tmp, f"tex_{k}.png")
        belt_texture(rng, tex, "crate")
        plastic = {"type": "plastic", "diffuse_reflectance": {"type": "bitmap", "filename": tex}, "nonlinear": True}
        shapes["floor"] = {"type": "rectangle", "to_world": big, "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.1, 0.1, 0.1]}}}
        shapes["crate"] = {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([0, 0, 0.001]).scale([half + 0.03, half + 0.03, 1]), "bsdf": plastic}
        wall_h = rng.uniform(0.08, 0.16)
        for i, (tx, ty, sx, sy) in enumerate([(half + 0.03, 0, 0.012, half + 0.04), (-half - 0.03, 0, 0.012, half + 0.04),
                                              (0, half + 0.03, half + 0.04, 0.012), (0, -half - 0.03, half + 0.04, 0.012)]):
            shapes[f"wall{i}"] = {"type": "cube", "to_world": mi.ScalarTransform4f().translate([tx, ty, wall_h / 2]).scale([sx, sy, wall_h / 2]), "bsdf": plastic}
        return kind, shapes, half
    half = rng.uniform(0.3, 0.45)
    tex = os.path.join(tmp, f"tex_{k}.png")
    belt_texture(rng, tex, "green" if kind == "belt_green" else "grey")
    shapes["floor"] = {"type": "rectangle", "to_world": mi.ScalarTransform4f().rotate([0, 0, 1], float(rng.uniform(0, 180))).scale([0.6, 3.0, 1]),
                       "bsdf": {"type": "roughplastic", "diffuse_reflectance": {"type": "bitmap", "filename": tex}, "alpha": float(rng.uniform(0.1, 0.4)), "nonlinear": True}}
    shapes["under"] = {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([0, 0, -0.05]).scale([3, 3, 1]),
                       "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.08, 0.08, 0.09]}}}
    return kind, shapes, min(half, 0.5)


def build_scene(rng, size, spp, tmp, k):
    kind, shapes, half = surface(rng, tmp, k)
    floor_z = 0.002
    hf = HeightField(0.7, floor_z)
    n = int(rng.integers(3, 13))
    # Wide enough that the pile stays about one or two layers deep (no towers).
    spread = min(half * 0.95, max(half * rng.uniform(0.55, 0.95), 0.06 * np.sqrt(n)))
    carcasses = []
    for i in range(n):
        v, f, vn, col = carcass_mesh(rng)
        R = random_rotation(rng)
        v = v @ R.T
        vn = vn @ R.T
        xy = rng.uniform(-spread, spread, 2)
        v[:, :2] += xy
        v[:, 2] += floor_z - v[:, 2].min()
        v[:, 2] += hf.drop(v)
        hf.add(v)
        carcasses.append((v, f, vn, col))
    for i, (v, f, vn, col) in enumerate(carcasses):
        props = mi.Properties()
        props["bsdf"] = mi.load_dict({
            "type": "principled",
            "base_color": {"type": "mesh_attribute", "name": "vertex_color"},
            "roughness": float(rng.uniform(0.3, 0.6)),
            "specular": float(rng.uniform(0.3, 0.6)),
            "clearcoat": float(rng.uniform(0.2, 0.9)),
            "clearcoat_gloss": float(rng.uniform(0.5, 0.95)),
            "sheen": float(rng.uniform(0.0, 0.4)),
        })
        m = mi.Mesh(f"carcass_{i:02d}", len(v), len(f), has_vertex_normals=True, props=props)
        m.add_attribute("vertex_color", 3, col.ravel().tolist())
        p = mi.traverse(m)
        p["vertex_positions"] = v.astype(np.float32).ravel()
        p["faces"] = f.ravel()
        p["vertex_normals"] = vn.astype(np.float32).ravel()
        p.update()
        shapes[f"carcass_{i:02d}"] = m
    # Camera: 0.75-1.35 m up (scaled by the surface's size, >= 0.4 m above the pile), tilt up to 28 degrees, any yaw, fov 35-65 degrees.
    fov = rng.uniform(35, 65)
    tilt = np.radians(rng.uniform(0, 28))
    yaw = rng.uniform(0, 2 * np.pi)
    top = max(float(v[:, 2].max()) for v, _, _, _ in carcasses)
    height = max(rng.uniform(0.75, 1.35) * (half / 0.35) ** 0.5, top + 0.4)
    target = np.array([*rng.uniform(-0.05, 0.05, 2), 0.0])
    dist = height / np.cos(tilt)
    origin = target + dist * np.array([np.sin(tilt) * np.cos(yaw), np.sin(tilt) * np.sin(yaw), np.cos(tilt)])
    up = [np.cos(yaw + np.pi / 2), np.sin(yaw + np.pi / 2), 0.0]
    cam = mi.ScalarTransform4f().look_at(origin=origin.tolist(), target=target.tolist(), up=up)
    # Lights: 1-3 rectangles 1.0-2.2 m up, 2700-7000 K, plus a dim environment of its own temperature.
    # Each light hangs at least 0.3 m above the camera: a one-sided area light's black
    # back must never stand between the camera and the pile.
    lights = {}
    raised = 0
    kelvin = rng.uniform(2700, 7000)
    for j in range(int(rng.integers(1, 4))):
        a = rng.uniform(0, 2 * np.pi)
        pos = [np.cos(a) * rng.uniform(0, 1.0), np.sin(a) * rng.uniform(0, 1.0), rng.uniform(1.0, 2.2)]
        floor_light = origin[2] + 0.3
        raised += int(pos[2] < floor_light)
        pos[2] = max(pos[2], floor_light)
        s = rng.uniform(0.2, 0.8)
        col = kelvin_rgb(kelvin * rng.uniform(0.9, 1.1)) * rng.uniform(4, 14) * (1.0 if j == 0 else rng.uniform(0.2, 0.6))
        lights[f"light{j}"] = {"type": "rectangle",
                               "to_world": mi.ScalarTransform4f().look_at(origin=pos, target=[0, 0, 0], up=[0, 1, 0]).scale([s, s, 1]),
                               "emitter": {"type": "area", "radiance": {"type": "rgb", "value": col.tolist()}}}
    env = (kelvin_rgb(rng.uniform(3000, 9000)) * rng.uniform(0.05, 0.3)).tolist()
    sensor = {"type": "perspective", "fov": float(fov), "to_world": cam,
              "film": {"type": "hdrfilm", "width": size, "height": size, "pixel_format": "rgb", "rfilter": {"type": "gaussian"}},
              "sampler": {"type": "independent", "sample_count": spp}}
    beauty = {"type": "scene", "integrator": {"type": "path", "max_depth": 5}, "sensor": sensor,
              "env": {"type": "constant", "radiance": {"type": "rgb", "value": env}}, **shapes, **lights}
    ids = {"type": "scene", "integrator": {"type": "aov", "aovs": "si:shape_index"},
           "sensor": {**sensor, "film": {"type": "hdrfilm", "width": size, "height": size, "pixel_format": "rgb", "rfilter": {"type": "box"}},
                      "sampler": {"type": "stratified", "sample_count": 1, "jitter": False}}, **shapes}
    exposure = rng.uniform(-0.4, 0.4)
    info = {"surface": str(kind), "carcasses": n, "kelvin": round(float(kelvin)), "fov": round(float(fov), 1),
            "tilt_deg": round(float(np.degrees(tilt)), 1), "height_m": round(float(height), 3),
            "lights_raised": raised}
    return beauty, ids, exposure, info


def tonemap(img, exposure):
    """Linear RGB to 8-bit sRGB: auto exposure on the 90th luminance percentile, a soft
    shoulder (Reinhard on luminance), the sRGB curve."""
    lum = img @ np.array([0.2126, 0.7152, 0.0722])
    scale = 0.75 / max(np.percentile(lum, 90), 1e-4) * 2.0 ** exposure
    x = img * scale
    x = x / (1 + 0.25 * x)
    x = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(np.clip(x, 0.0031308, None), 1 / 2.4) - 0.055)
    return (np.clip(x, 0, 1) * 255 + 0.5).astype(np.uint8)


def render_one(k, args, tmp):
    rng = np.random.default_rng([args.seed, k])
    t0 = time.time()
    beauty, ids, exposure, info = build_scene(rng, args.size, args.spp, tmp, k)
    t1 = time.time()
    scene = mi.load_dict(beauty)
    img = np.array(mi.render(scene, seed=int(rng.integers(2**31))))
    t2 = time.time()
    id_scene = mi.load_dict(ids)
    names = [s.id() for s in id_scene.shapes()]
    aov = np.array(mi.render(id_scene))[..., 0]
    idx = np.rint(aov).astype(int)
    if np.any(np.abs(aov - idx) > 1e-4) or idx.max() > len(names):
        raise SystemExit(f"image {k}: shape-index AOV not integral")
    # Shape index i+1 is scene.shapes()[i]; 0 is a miss.
    anns = []
    for si, name in enumerate(names, start=1):
        if not name.startswith("carcass_"):
            continue
        m = idx == si
        if m.sum() < MIN_VISIBLE_PX:
            continue
        rle = mask_utils.encode(np.asfortranarray(m.astype(np.uint8)))
        anns.append({"segmentation": {"size": rle["size"], "counts": rle["counts"].decode()},
                     "area": float(mask_utils.area(rle)), "bbox": [float(x) for x in mask_utils.toBbox(rle)],
                     "category_id": 1, "iscrowd": 0, "source": name})
    info.update({"build_s": round(t1 - t0, 2), "render_s": round(t2 - t1, 2), "labels_s": round(time.time() - t2, 2)})
    return tonemap(img, exposure), anns, info


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True)
    ap.add_argument("--count", type=int, default=100)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--quality", type=int, default=90)
    args = ap.parse_args()
    dr.set_thread_count(args.threads)
    os.makedirs(os.path.join(args.out, "images"), exist_ok=True)
    os.makedirs(os.path.join(args.out, "sidecars"), exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.count):
            name = f"xd2_{k:05d}.jpg"
            jpg = os.path.join(args.out, "images", name)
            side = os.path.join(args.out, "sidecars", f"xd2_{k:05d}.json")
            if os.path.exists(jpg) and os.path.exists(side):
                continue
            t = time.time()
            img, anns, info = render_one(k, args, tmp)
            info["total_s"] = round(time.time() - t, 2)
            for path, write in ((jpg, lambda p: Image.fromarray(img).save(p, "JPEG", quality=args.quality)),
                                (side, lambda p: json.dump({"file_name": name, "annotations": anns, "info": info}, open(p, "w")))):
                part = path + ".part"
                write(part)
                os.replace(part, path)  # atomic: a killed run leaves no half file
            print(f"{name}: {len(anns)} instances, {info}", flush=True)
    images, annotations = [], []
    for k in range(args.count):
        s = json.load(open(os.path.join(args.out, "sidecars", f"xd2_{k:05d}.json")))
        images.append({"id": k + 1, "file_name": s["file_name"], "width": args.size, "height": args.size})
        for a in s["annotations"]:
            a = {key: v for key, v in a.items() if key != "source"}
            annotations.append({"id": len(annotations) + 1, "image_id": k + 1, **a})
    coco = {"images": images, "annotations": annotations, "categories": [{"id": 1, "name": "carcass"}]}
    part = os.path.join(args.out, "annotations.json.part")
    with open(part, "w") as fh:
        json.dump(coco, fh)
    os.replace(part, os.path.join(args.out, "annotations.json"))
    print(f"{len(images)} images, {len(annotations)} instances", file=sys.stderr)


if __name__ == "__main__":
    main()
