#!/usr/bin/env python3
"""Cross-domain validation set for chicktrain, rendered with Blender Cycles (bpy wheel).

An INDEPENDENT measurement domain: a different renderer (Cycles path tracing), a
carcass model built here from Blender primitives (not chicktrain's assets/carcass.glb),
Blender rigid-body piling, its own materials, lights and belts. chicktrain never trains
on it and its renderer is never tuned against it.

    python make_crossdomain.py --out DIR --count 100 --size 256 --seed 0 --spp 16 --threads 1

Writes DIR/images/xd_00000.jpg ... (JPEG q90), DIR/sidecars/xd_00000.json (per-image
annotations, so the run is resumable: finished images are skipped) and, at the end,
DIR/annotations.json (COCO, segmentation as RLE with str counts, one category
"carcass"). Image k (0-based) has image id k+1 and is a pure function of (--seed, k,
--size, --spp), whatever was rendered before it.

Instance masks come from a second Cycles render of the same frame in which every
carcass carries a flat emission shader whose linear value encodes its index, the plate
and world are black, 1 sample, 0.01 px pixel filter (no anti-aliasing), written as
32-bit float EXR and read back exactly.
"""

import argparse
import json
import math
import os
import random
import sys
import time

import bpy  # noqa: I001  (bpy must come first: it provides bmesh and mathutils)
import bmesh
import numpy as np
from mathutils import Euler, Matrix, Vector
from pycocotools import mask as mask_util

MIN_PIXELS = 100  # visible pixels below which an instance is dropped
ID_SCALE = 64.0  # mask pass: emission value = (index + 1) / ID_SCALE, exact in float32


# --------------------------------------------------------------------------- helpers

def log(*a):
    print(*a, file=sys.stderr, flush=True)


def blackbody_rgb(kelvin):
    """Approximate linear RGB of a black body (normalised so max channel = 1)."""
    t = kelvin / 100.0
    if t <= 66:
        r = 255.0
        g = 99.4708025861 * math.log(t) - 161.1195681661
        b = 0.0 if t <= 19 else 138.5177312231 * math.log(t - 10) - 305.0447927307
    else:
        r = 329.698727446 * ((t - 60) ** -0.1332047592)
        g = 288.1221695283 * ((t - 60) ** -0.0755148492)
        b = 255.0
    srgb = [min(max(c, 0.0), 255.0) / 255.0 for c in (r, g, b)]
    lin = [c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4 for c in srgb]
    m = max(lin)
    return tuple(c / m for c in lin)


def link(ob):
    bpy.context.scene.collection.objects.link(ob)
    return ob


def new_node(nt, kind, loc=(0, 0), **inputs):
    n = nt.nodes.new(kind)
    n.location = loc
    for k, v in inputs.items():
        n.inputs[k].default_value = v
    return n


# --------------------------------------------------------------------------- carcass

def ellipsoid(bm, center, radii, rot=(0, 0, 0), segs=24, rings=12):
    """Add a UV-sphere ellipsoid to bm; returns its vertices."""
    geom = bmesh.ops.create_uvsphere(bm, u_segments=segs, v_segments=rings, radius=1.0)
    verts = geom["verts"]
    m = (Matrix.Translation(Vector(center)) @ Euler(rot, "XYZ").to_matrix().to_4x4()
         @ Matrix.Diagonal((radii[0], radii[1], radii[2], 1.0)))
    bmesh.ops.transform(bm, matrix=m, verts=verts)
    return verts


def tapered_limb(bm, p0, p1, r0, r1, segs=16, rings=10):
    """A capsule-like limb from p0 (radius r0) to p1 (radius r1): a sphere stretched
    along its axis with the radius interpolated along it."""
    geom = bmesh.ops.create_uvsphere(bm, u_segments=segs, v_segments=rings, radius=1.0)
    verts = geom["verts"]
    p0, p1 = Vector(p0), Vector(p1)
    axis = p1 - p0
    length = axis.length
    rot = Vector((0, 0, 1)).rotation_difference(axis.normalized()).to_matrix()
    for v in verts:
        x, y, z = v.co
        s = (z + 1.0) / 2.0  # 0 at p0 end, 1 at p1 end
        r = r0 + (r1 - r0) * s
        # bulge of the muscle near the thick end
        r *= 1.0 + 0.25 * math.sin(math.pi * min(1.0, s * 1.4)) * (1 - s)
        local = Vector((x * r, y * r, s * length))
        v.co = p0 + rot @ local
    return verts


def build_carcass(rng, name):
    """A plucked, eviscerated, headless chicken carcass (feet cut at the hock) from
    primitives, voxel-remeshed to one mesh. Local frame: +x neck, +z breast.
    Returns (object, dict of parts present)."""
    bm = bmesh.new()
    L = 1.0  # body length in local units; scaled to metres at the end
    w = rng.uniform(0.6, 0.72)  # width / length
    h = rng.uniform(0.48, 0.58)  # depth / length
    breast = rng.uniform(0.04, 0.08)  # breast mound height
    body = ellipsoid(bm, (0, 0, 0), (L / 2, w / 2, h / 2), segs=40, rings=20)
    for v in body:
        x, y, z = v.co
        u = x / (L / 2)  # -1 tail .. +1 neck
        # egg shape: broader at the shoulders/breast end, narrow towards the tail
        k = 1.0 + 0.12 * u
        y *= k
        if z > 0:
            # breast: two rounded mounds with the keel ridge between them
            front = math.exp(-((u - 0.15) / 0.7) ** 2)
            mounds = (math.exp(-((y - 0.16 * w) / (0.14 * w)) ** 2)
                      + math.exp(-((y + 0.16 * w) / (0.14 * w)) ** 2))
            keel = 0.6 * math.exp(-(y / (0.03 * w)) ** 2)
            z += breast * front * (mounds + keel) * (z / (h / 2))
        else:
            z *= 0.82  # flatter back
        v.co = (x, y, z)

    parts = {"wing_l": False, "wing_r": False, "leg_l": False, "leg_r": False}
    for side, sgn in (("l", 1.0), ("r", -1.0)):
        # thigh + drumstick; sometimes missing (cut / torn off)
        if rng.random() < 0.88:
            parts["leg_" + side] = True
            # thigh: a broad bulge on the rear side of the body
            tx = rng.uniform(-0.16, -0.06)
            ty = sgn * w * rng.uniform(0.4, 0.46)
            tz = rng.uniform(0.0, 0.06)
            ellipsoid(bm, (tx, ty, tz), (0.22, 0.13, 0.13),
                      rot=(0, -0.2, sgn * rng.uniform(0.1, 0.4)), segs=20, rings=10)
            if rng.random() < 0.92:  # drumstick: runs back past the tail, legs in a V
                knee = Vector((rng.uniform(-0.2, -0.08), sgn * w * rng.uniform(0.48, 0.56),
                               rng.uniform(0.04, 0.14)))
                out = rng.uniform(-0.3, 0.4)  # <0: hocks cross behind the tail
                length = rng.uniform(0.46, 0.58)
                d = Vector((-1.0, sgn * out, rng.uniform(0.0, 0.45))).normalized()
                hock = knee + length * d
                tapered_limb(bm, knee, hock, rng.uniform(0.095, 0.11), rng.uniform(0.042, 0.05))
                ellipsoid(bm, hock, (0.055, 0.05, 0.05), segs=12, rings=6)  # hock knuckle
        # wing folded along the side; sometimes missing or only partial
        if rng.random() < 0.85:
            parts["wing_" + side] = True
            sx = rng.uniform(0.18, 0.26)
            sy = sgn * w * rng.uniform(0.5, 0.58)
            sz = rng.uniform(-0.06, 0.08)
            spread = rng.uniform(0.0, 0.7)  # 0 = tucked along the side, larger = opened out
            upper_len = rng.uniform(0.17, 0.21)
            elbow = Vector((sx - upper_len * math.cos(spread),
                            sy + sgn * upper_len * math.sin(spread), sz + rng.uniform(-0.04, 0.02)))
            tapered_limb(bm, (sx, sy, sz), elbow, rng.uniform(0.08, 0.095), 0.055)
            if rng.random() < 0.9:  # forearm folds forward again (or trails when opened)
                fore_len = rng.uniform(0.16, 0.2)
                if spread < 0.35:  # tucked: the forearm runs forward again along the side
                    f = rng.uniform(0.05, 0.4)
                    d = Vector((math.cos(f), sgn * math.sin(f), 0.0))
                else:  # opened: the forearm trails backwards and outwards
                    f = rng.uniform(0.3, 1.1)
                    d = Vector((-math.cos(f), sgn * math.sin(f), 0.0))
                wrist = elbow + fore_len * d + Vector((0, 0, rng.uniform(-0.05, 0.0)))
                tapered_limb(bm, elbow, wrist, 0.06, 0.04)
                if rng.random() < 0.7:  # wing tip
                    tdir = (wrist - elbow).normalized()
                    tip = wrist + tdir * rng.uniform(0.05, 0.08) + Vector((0, sgn * 0.02, -0.01))
                    tapered_limb(bm, wrist, tip, 0.038, 0.025)
    # neck stump with loose skin, and the tail ("parson's nose")
    ellipsoid(bm, (L * 0.47, 0, rng.uniform(-0.06, 0.0)),
              (rng.uniform(0.08, 0.13), 0.085, 0.075), rot=(0, 0.3, 0), segs=16, rings=8)
    ellipsoid(bm, (-L * 0.5, 0, -0.08), (0.07, 0.06, 0.05), rot=(0, -0.4, 0), segs=12, rings=6)

    me = bpy.data.meshes.new(name + "_src")
    bm.to_mesh(me)
    bm.free()
    src = link(bpy.data.objects.new(name + "_src", me))

    tex = bpy.data.textures.new(name + "_lumps", "CLOUDS")
    tex.noise_scale = rng.uniform(0.12, 0.2)
    tex.noise_depth = 2
    rm = src.modifiers.new("remesh", "REMESH")
    rm.mode = "VOXEL"
    rm.voxel_size = 0.018
    sm2 = src.modifiers.new("smooth2", "SMOOTH")
    sm2.factor = 0.5
    sm2.iterations = 4
    dp = src.modifiers.new("lumps", "DISPLACE")
    dp.texture = tex
    dp.strength = rng.uniform(0.01, 0.025)
    dp.mid_level = 0.5
    dp.texture_coords = "LOCAL"

    dg = bpy.context.evaluated_depsgraph_get()
    mesh = bpy.data.meshes.new_from_object(src.evaluated_get(dg))
    bpy.data.objects.remove(src)
    bpy.data.meshes.remove(me)
    bpy.data.textures.remove(tex)

    # real size: 20-31 cm long carcass (about 1.2-2.6 kg birds)
    size = rng.uniform(0.18, 0.27)
    mesh.transform(Matrix.Diagonal((size, size * rng.uniform(0.95, 1.05), size, 1.0)))
    for p in mesh.polygons:
        p.use_smooth = True
    ob = link(bpy.data.objects.new(name, mesh))
    return ob, parts, size


def skin_material(rng, name, size):
    """Principled BSDF with subsurface; pale pink-to-yellow base varied by noise, red
    patches (bruises, blood spots), follicle bumps. Parameters drawn per instance."""
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    out = new_node(nt, "ShaderNodeOutputMaterial", (900, 0))
    bsdf = new_node(nt, "ShaderNodeBsdfPrincipled", (600, 0))
    nt.links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    tc = new_node(nt, "ShaderNodeTexCoord", (-900, 0))
    mp = new_node(nt, "ShaderNodeMapping", (-700, 0))
    mp.inputs["Location"].default_value = tuple(rng.uniform(-50, 50, 3))
    nt.links.new(tc.outputs["Object"], mp.inputs["Vector"])

    # base colour: between a pale pink and a yellowish skin, drawn per instance
    pink = np.array([0.72, 0.38, 0.30])
    yellow = np.array([0.74, 0.52, 0.24])
    t = rng.uniform(0.0, 1.0)
    base = (1 - t) * pink + t * yellow
    base *= rng.uniform(0.75, 1.05)
    alt = base * np.array([rng.uniform(0.9, 1.05), rng.uniform(0.82, 0.95), rng.uniform(0.75, 0.95)])
    red = np.array([rng.uniform(0.55, 0.75), rng.uniform(0.18, 0.3), rng.uniform(0.16, 0.26)])

    n1 = new_node(nt, "ShaderNodeTexNoise", (-500, 200), Scale=rng.uniform(6, 14), Detail=4.0,
                  Roughness=0.55)
    nt.links.new(mp.outputs["Vector"], n1.inputs["Vector"])
    ramp = nt.nodes.new("ShaderNodeValToRGB")
    ramp.location = (-300, 200)
    ramp.color_ramp.elements[0].position = 0.35
    ramp.color_ramp.elements[0].color = (*base, 1)
    ramp.color_ramp.elements[1].position = 0.7
    ramp.color_ramp.elements[1].color = (*alt, 1)
    nt.links.new(n1.outputs["Fac"], ramp.inputs["Fac"])

    # redness: low-frequency patches, thresholded
    n2 = new_node(nt, "ShaderNodeTexNoise", (-500, -100), Scale=rng.uniform(2, 6), Detail=3.0)
    nt.links.new(mp.outputs["Vector"], n2.inputs["Vector"])
    rr = nt.nodes.new("ShaderNodeValToRGB")
    rr.location = (-300, -100)
    redness = rng.uniform(0.0, 1.0)
    rr.color_ramp.elements[0].position = 0.72 - 0.12 * redness
    rr.color_ramp.elements[0].color = (0, 0, 0, 1)
    rr.color_ramp.elements[1].position = 0.82 - 0.08 * redness
    amt = 0.25 + 0.5 * redness
    rr.color_ramp.elements[1].color = (amt, amt, amt, 1)
    nt.links.new(n2.outputs["Fac"], rr.inputs["Fac"])
    # extremities (wing tips, hocks, neck skin) redder: ellipsoidal distance from the body
    dv = nt.nodes.new("ShaderNodeVectorMath")
    dv.operation = "DIVIDE"
    dv.location = (-500, -250)
    dv.inputs[1].default_value = (0.5 * size, 0.36 * size, 0.28 * size)
    nt.links.new(tc.outputs["Object"], dv.inputs[0])
    ln = nt.nodes.new("ShaderNodeVectorMath")
    ln.operation = "LENGTH"
    ln.location = (-350, -250)
    nt.links.new(dv.outputs["Vector"], ln.inputs[0])
    mr = nt.nodes.new("ShaderNodeMapRange")
    mr.location = (-200, -250)
    mr.inputs["From Min"].default_value = rng.uniform(0.95, 1.15)
    mr.inputs["From Max"].default_value = rng.uniform(1.5, 1.9)
    mr.inputs["To Max"].default_value = rng.uniform(0.3, 0.85)
    nt.links.new(ln.outputs["Value"], mr.inputs["Value"])
    mx = nt.nodes.new("ShaderNodeMath")
    mx.operation = "MAXIMUM"
    mx.location = (-150, -100)
    nt.links.new(rr.outputs["Color"], mx.inputs[0])
    nt.links.new(mr.outputs["Result"], mx.inputs[1])
    mix = nt.nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    mix.location = (-50, 100)
    nt.links.new(mx.outputs["Value"], mix.inputs["Factor"])
    nt.links.new(ramp.outputs["Color"], mix.inputs[6])
    mix.inputs[7].default_value = (*red, 1)
    nt.links.new(mix.outputs[2], bsdf.inputs["Base Color"])

    bsdf.inputs["Subsurface Weight"].default_value = rng.uniform(0.15, 0.4)
    bsdf.inputs["Subsurface Radius"].default_value = (1.0, 0.45, 0.3)
    bsdf.inputs["Subsurface Scale"].default_value = rng.uniform(0.003, 0.008)
    bsdf.inputs["Roughness"].default_value = rng.uniform(0.3, 0.55)  # wet skin
    bsdf.inputs["Specular IOR Level"].default_value = rng.uniform(0.45, 0.6)
    bsdf.inputs["Coat Weight"].default_value = rng.uniform(0.0, 0.25)  # water film
    bsdf.inputs["Coat Roughness"].default_value = rng.uniform(0.05, 0.2)

    # feather follicles + fine wrinkles as bump
    vor = new_node(nt, "ShaderNodeTexVoronoi", (-300, -400), Scale=rng.uniform(180, 300))
    vor.feature = "F1"
    nt.links.new(mp.outputs["Vector"], vor.inputs["Vector"])
    n3 = new_node(nt, "ShaderNodeTexNoise", (-300, -600), Scale=rng.uniform(30, 60), Detail=6.0)
    nt.links.new(mp.outputs["Vector"], n3.inputs["Vector"])
    add = nt.nodes.new("ShaderNodeMath")
    add.operation = "ADD"
    add.location = (0, -450)
    nt.links.new(vor.outputs["Distance"], add.inputs[0])
    nt.links.new(n3.outputs["Fac"], add.inputs[1])
    bump = new_node(nt, "ShaderNodeBump", (300, -300), Strength=rng.uniform(0.15, 0.35),
                    Distance=0.0015)
    nt.links.new(add.outputs[0], bump.inputs["Height"])
    nt.links.new(bump.outputs["Normal"], bsdf.inputs["Normal"])
    nt.links.new(bump.outputs["Normal"], bsdf.inputs["Coat Normal"])
    return mat


# --------------------------------------------------------------------------- scene

def plate_material(rng, kind):
    mat = bpy.data.materials.new("plate_" + kind)
    mat.use_nodes = True
    nt = mat.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    tc = new_node(nt, "ShaderNodeTexCoord", (-900, 0))
    mp = new_node(nt, "ShaderNodeMapping", (-700, 0))
    mp.inputs["Location"].default_value = tuple(rng.uniform(-20, 20, 3))
    mp.inputs["Rotation"].default_value = (0, 0, rng.uniform(-0.05, 0.05))
    nt.links.new(tc.outputs["Object"], mp.inputs["Vector"])
    if kind == "steel":
        g = rng.uniform(0.55, 0.75)
        bsdf.inputs["Base Color"].default_value = (g, g, g * rng.uniform(0.97, 1.03), 1)
        bsdf.inputs["Metallic"].default_value = 1.0
        # brushed: noise stretched along x drives roughness; wet smears
        mp.inputs["Scale"].default_value = (2.0, 80.0, 2.0)
        n = new_node(nt, "ShaderNodeTexNoise", (-500, 0), Scale=rng.uniform(2, 6), Detail=8.0)
        nt.links.new(mp.outputs["Vector"], n.inputs["Vector"])
        mr = nt.nodes.new("ShaderNodeMapRange")
        mr.location = (-250, 0)
        lo = rng.uniform(0.15, 0.3)
        mr.inputs["To Min"].default_value = lo
        mr.inputs["To Max"].default_value = lo + rng.uniform(0.1, 0.3)
        nt.links.new(n.outputs["Fac"], mr.inputs["Value"])
        nt.links.new(mr.outputs["Result"], bsdf.inputs["Roughness"])
        bsdf.inputs["Anisotropic"].default_value = rng.uniform(0.3, 0.8)
    else:
        if kind == "dark":
            g = rng.uniform(0.02, 0.07)
            col = (g, g, g * rng.uniform(0.9, 1.2))
        else:  # light modular plastic belt: white, light blue or blue
            col = [(0.75, 0.76, 0.74), (0.35, 0.55, 0.75), (0.08, 0.22, 0.55)][rng.integers(3)]
            col = tuple(c * rng.uniform(0.85, 1.05) for c in col)
        bsdf.inputs["Base Color"].default_value = (*col, 1)
        bsdf.inputs["Roughness"].default_value = rng.uniform(0.4, 0.75)
        bsdf.inputs["Specular IOR Level"].default_value = rng.uniform(0.25, 0.5)
        # modular belt: slats across the belt direction (wave bands) + small holes
        pitch = rng.uniform(20, 40)
        wave = new_node(nt, "ShaderNodeTexWave", (-500, 0), Scale=pitch, Distortion=0.0)
        wave.wave_type = "BANDS"
        wave.bands_direction = "X"
        wave.wave_profile = "SAW" if rng.random() < 0.5 else "SIN"
        nt.links.new(mp.outputs["Vector"], wave.inputs["Vector"])
        bump = new_node(nt, "ShaderNodeBump", (-200, -100), Strength=rng.uniform(0.3, 0.8),
                        Distance=0.002)
        nt.links.new(wave.outputs["Fac"], bump.inputs["Height"])
        nt.links.new(bump.outputs["Normal"], bsdf.inputs["Normal"])
    return mat


def add_box(name, loc, dims, mat=None, rot=(0, 0, 0)):
    me = bpy.data.meshes.new(name)
    bm = bmesh.new()
    bmesh.ops.create_cube(bm, size=1.0)
    bm.to_mesh(me)
    bm.free()
    me.transform(Matrix.Diagonal((*dims, 1.0)))
    ob = link(bpy.data.objects.new(name, me))
    ob.location = loc
    ob.rotation_euler = rot
    if mat is not None:
        me.materials.append(mat)
    return ob


def setup_render(sc, size, spp, threads, seed):
    sc.render.engine = "CYCLES"
    cy = sc.cycles
    cy.device = "CPU"
    cy.samples = spp
    cy.use_adaptive_sampling = False
    cy.seed = seed
    cy.use_animated_seed = False
    cy.max_bounces = 6
    cy.diffuse_bounces = 3
    cy.glossy_bounces = 3
    cy.transmission_bounces = 4
    cy.transparent_max_bounces = 4
    cy.caustics_reflective = False
    cy.caustics_refractive = False
    cy.sample_clamp_indirect = 5.0
    import _cycles
    cy.use_denoising = bool(getattr(_cycles, "with_openimagedenoise", False))
    if cy.use_denoising:
        cy.denoiser = "OPENIMAGEDENOISE"
        cy.denoising_input_passes = "RGB_ALBEDO_NORMAL"
        cy.denoising_prefilter = "ACCURATE"
    cy.filter_width = 1.5
    sc.render.resolution_x = size
    sc.render.resolution_y = size
    sc.render.resolution_percentage = 100
    sc.render.threads_mode = "FIXED"
    sc.render.threads = threads
    sc.render.use_persistent_data = False
    sc.render.film_transparent = False
    sc.view_settings.view_transform = "AgX"
    for look in ("AgX - Punchy", "Punchy", "AgX - Medium High Contrast", "None"):
        try:
            sc.view_settings.look = look
            break
        except TypeError:
            continue
    # no metadata (dates, render times) in the files, so reruns are byte-comparable
    for prop in dir(sc.render):
        if prop.startswith("use_stamp"):
            setattr(sc.render, prop, False)
    sc.render.image_settings.file_format = "JPEG"
    sc.render.image_settings.quality = 90
    sc.render.image_settings.color_mode = "RGB"


def build_scene(rng, size, spp, threads, blender_seed):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    setup_render(sc, size, spp, threads, blender_seed)
    info = {}

    # ---- belt / plate
    kind = rng.choice(["steel", "dark", "modular"], p=[0.4, 0.35, 0.25])
    info["surface"] = str(kind)
    pmat = plate_material(rng, kind)
    floor = add_box("plate", (0, 0, -0.02), (4.0, 4.0, 0.04), pmat)
    rails = []
    info["rails"] = bool(rng.random() < 0.5)
    belt_half = rng.uniform(0.3, 0.45)
    if info["rails"]:
        rmat = plate_material(rng, "steel")
        for s in (1, -1):
            rails.append(add_box("rail", (0, s * (belt_half + 0.02), 0.04), (4.0, 0.03, 0.08), rmat))

    # ---- rigid-body world
    bpy.ops.rigidbody.world_add()
    rbw = sc.rigidbody_world
    if rbw.collection is None:
        rbw.collection = bpy.data.collections.new("RigidBodyWorld")
    rbw.substeps_per_frame = 10
    rbw.solver_iterations = 12
    frames = 120
    rbw.point_cache.frame_start = 1
    rbw.point_cache.frame_end = frames

    def passive(ob, friction):
        rbw.collection.objects.link(ob)
        ob.rigid_body.type = "PASSIVE"
        ob.rigid_body.collision_shape = "BOX"
        ob.rigid_body.friction = friction
        ob.rigid_body.restitution = 0.0

    passive(floor, rng.uniform(0.4, 0.8))
    for r in rails:
        passive(r, 0.4)
    # invisible guides keep the pile together (a chute / side guides upstream)
    guide = rng.uniform(0.22, 0.4)
    walls = []
    for s in (1, -1):
        walls.append(add_box("wall", (s * (guide + 0.05), 0, 0.3), (0.1, 2.0, 0.6)))
        if not info["rails"]:
            walls.append(add_box("wall", (0, s * (guide + 0.05), 0.3), (2.0, 0.1, 0.6)))
    for wl in walls:
        passive(wl, 0.3)

    # ---- carcasses dropped one after another
    n = int(rng.integers(3, 13))
    carcasses = []
    spread = min(guide - 0.12, 0.05 + 0.04 * math.sqrt(n))
    for i in range(n):
        ob, parts, size = build_carcass(rng, f"carcass_{i:02d}")
        ob.data.materials.append(skin_material(rng, f"skin_{i:02d}", size))
        ob.location = (rng.uniform(-spread, spread), rng.uniform(-spread, spread),
                       0.15 + 0.13 * i + rng.uniform(0, 0.05))
        # mostly breast-up or breast-down, sometimes on the side; any heading
        roll = rng.choice([0.0, math.pi, math.pi / 2, -math.pi / 2], p=[0.45, 0.3, 0.125, 0.125])
        ob.rotation_euler = (roll + rng.normal(0, 0.35), rng.normal(0, 0.35),
                             rng.uniform(0, 2 * math.pi))
        rbw.collection.objects.link(ob)
        rb = ob.rigid_body
        rb.type = "ACTIVE"
        rb.collision_shape = "CONVEX_HULL"
        rb.collision_margin = 0.002
        rb.mass = 1.8 * (size / 0.26) ** 3
        rb.friction = rng.uniform(0.5, 0.9)
        rb.restitution = 0.0
        rb.linear_damping = 0.3
        rb.angular_damping = 0.5
        carcasses.append(ob)
    info["n_dropped"] = n

    t0 = time.time()
    for f in range(1, frames + 1):
        sc.frame_set(f)
    info["sim_s"] = round(time.time() - t0, 2)
    # freeze the settled poses, then drop the simulation
    poses = [ob.matrix_world.copy() for ob in carcasses]
    bpy.ops.rigidbody.world_remove()
    for ob, m in zip(carcasses, poses):
        ob.matrix_world = m
    for wl in walls:
        bpy.data.objects.remove(wl)
    sc.frame_set(frames)
    # a carcass that escaped the plate (rare) is removed from the scene
    kept = []
    for ob in carcasses:
        p = ob.matrix_world.translation
        if p.z < -0.05 or abs(p.x) > 1.5 or abs(p.y) > 1.5:
            bpy.data.objects.remove(ob)
        else:
            kept.append(ob)
    info["n_escaped"] = len(carcasses) - len(kept)
    carcasses = kept

    # ---- camera: above the pile, tilt <= 10 deg, random yaw and height
    pts = np.array([tuple(ob.matrix_world.translation) for ob in carcasses])
    c = np.median(pts, axis=0)
    # frame most of the pile; a carcass that slid far away may be cropped
    dist = np.abs(pts[:, :2] - c[:2]).max(axis=1)
    ext = float(np.clip(np.percentile(dist, 85) + 0.15, 0.22, 0.6))
    cam_data = bpy.data.cameras.new("cam")
    cam_data.lens = float(rng.uniform(28, 50))
    cam_data.sensor_width = 36.0
    cam = link(bpy.data.objects.new("cam", cam_data))
    fov = 2 * math.atan(18.0 / cam_data.lens)
    height = ext * rng.uniform(0.95, 1.35) / math.tan(fov / 2)
    tilt = math.radians(rng.uniform(0, 10))
    tdir = rng.uniform(0, 2 * math.pi)
    cam.location = (c[0] + rng.normal(0, 0.03) + height * math.tan(tilt) * math.cos(tdir),
                    c[1] + rng.normal(0, 0.03) + height * math.tan(tilt) * math.sin(tdir),
                    height)
    target = Vector((c[0], c[1], 0.0))
    look = (target - Vector(cam.location)).normalized()
    cam.rotation_euler = look.to_track_quat("-Z", "Y").to_euler()
    cam.rotation_euler.rotate_axis("Z", rng.uniform(0, 2 * math.pi))
    sc.camera = cam
    info["cam_height"] = round(height, 3)
    info["tilt_deg"] = round(math.degrees(tilt), 2)

    # ---- lights
    lights = []
    nl = int(rng.integers(1, 4))
    for j in range(nl):
        kelvin = rng.uniform(3000, 6500)
        if j == 0 or rng.random() < 0.7:
            ld = bpy.data.lights.new(f"area{j}", "AREA")
            ld.shape = "RECTANGLE"
            ld.size = rng.uniform(0.4, 1.6)
            ld.size_y = rng.uniform(0.4, 1.6)
            r = rng.uniform(0.0, 1.2)
            a = rng.uniform(0, 2 * math.pi)
            z = rng.uniform(1.0, 2.2)
            ld.energy = rng.uniform(60, 200) * (z * z + r * r) / 2.0 * (1.0 if j == 0 else 0.5)
            lo = link(bpy.data.objects.new(f"area{j}", ld))
            lo.location = (c[0] + r * math.cos(a), c[1] + r * math.sin(a), z)
            d = (Vector((c[0], c[1], 0)) - lo.location).normalized()
            lo.rotation_euler = d.to_track_quat("-Z", "Y").to_euler()
        else:
            ld = bpy.data.lights.new(f"sun{j}", "SUN")
            ld.energy = rng.uniform(0.5, 2.5)
            ld.angle = math.radians(rng.uniform(2, 30))
            lo = link(bpy.data.objects.new(f"sun{j}", ld))
            lo.rotation_euler = (rng.uniform(0, 0.6), rng.uniform(-0.6, 0.6), rng.uniform(0, 6.3))
        ld.color = blackbody_rgb(kelvin)
        lights.append(lo)
    info["lights"] = nl

    # ---- world: dim coloured ambient (hall lighting)
    world = bpy.data.worlds.new("world")
    bg = world.node_tree.nodes["Background"]
    wk = blackbody_rgb(rng.uniform(3500, 7500))
    bg.inputs["Color"].default_value = (*wk, 1)
    bg.inputs["Strength"].default_value = rng.uniform(0.05, 0.35)
    sc.world = world
    sc.view_settings.exposure = float(rng.uniform(-0.4, 0.4))
    return sc, carcasses, [floor] + rails, lights, info


# --------------------------------------------------------------------------- masks

def render_id_mask(sc, carcasses, others, lights, exr_path):
    """Second render: emission (i+1)/ID_SCALE per carcass, black elsewhere, 1 spp,
    0.01 px filter, no denoise, float EXR. Returns an int array (H, W), 0 = none."""
    for i, ob in enumerate(carcasses):
        m = bpy.data.materials.new(f"id_{i}")
        m.use_nodes = True
        nt = m.node_tree
        nt.nodes.clear()
        out = nt.nodes.new("ShaderNodeOutputMaterial")
        em = nt.nodes.new("ShaderNodeEmission")
        v = (i + 1) / ID_SCALE
        em.inputs["Color"].default_value = (v, v, v, 1)
        em.inputs["Strength"].default_value = 1.0
        nt.links.new(em.outputs["Emission"], out.inputs["Surface"])
        ob.data.materials[0] = m
    black = bpy.data.materials.new("id_black")
    black.use_nodes = True
    nt = black.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    em = nt.nodes.new("ShaderNodeEmission")
    em.inputs["Color"].default_value = (0, 0, 0, 1)
    nt.links.new(em.outputs["Emission"], out.inputs["Surface"])
    for ob in others:  # rails etc. occlude carcasses; the plate is simply black
        for k in range(len(ob.data.materials)):
            ob.data.materials[k] = black
    for lo in lights:
        lo.hide_render = True
    sc.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    cy = sc.cycles
    cy.samples = 1
    cy.use_denoising = False
    cy.filter_width = 0.01
    cy.max_bounces = 0
    cy.sample_clamp_direct = 0.0
    cy.sample_clamp_indirect = 0.0
    sc.view_settings.view_transform = "Standard"
    sc.view_settings.exposure = 0.0
    sc.render.dither_intensity = 0.0
    st = sc.render.image_settings
    st.file_format = "OPEN_EXR"
    st.color_depth = "32"
    st.exr_codec = "ZIP"
    st.color_mode = "RGB"
    sc.render.filepath = exr_path
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(exr_path)
    w, h = img.size
    px = np.empty(w * h * 4, dtype=np.float32)
    img.pixels.foreach_get(px)
    bpy.data.images.remove(img)
    px = px.reshape(h, w, 4)[::-1, :, 0]  # Blender rows are bottom-up
    ids = np.rint(px * ID_SCALE).astype(np.int32)
    err = np.abs(px * ID_SCALE - ids).max()
    if err > 1e-3:
        raise RuntimeError(f"id pass not exact (max deviation {err})")
    return ids


# --------------------------------------------------------------------------- main

def strip_jpeg_metadata(path):
    """Drop COM and APPn (n >= 1) segments (Blender writes render stats and dates
    there) without re-encoding: the image data is untouched."""
    with open(path, "rb") as f:
        data = f.read()
    assert data[:2] == b"\xff\xd8", path
    out = bytearray(data[:2])
    i = 2
    while i < len(data):
        if data[i] != 0xFF:
            raise ValueError(f"{path}: bad JPEG marker at {i}")
        marker = data[i + 1]
        if marker == 0xDA:  # start of scan: the rest is entropy-coded data
            out += data[i:]
            break
        seg_len = int.from_bytes(data[i + 2:i + 4], "big")
        if not (marker == 0xFE or 0xE1 <= marker <= 0xEF):
            out += data[i:i + 2 + seg_len]
        i += 2 + seg_len
    with open(path, "wb") as f:
        f.write(bytes(out))


def render_one(k, args, img_dir, side_dir, tmp_dir):
    name = f"xd_{k:05d}"
    rng = np.random.default_rng([args.seed, k])
    random.seed(args.seed * 1_000_003 + k)
    blender_seed = int(rng.integers(0, 2**31 - 1))
    t0 = time.time()
    sc, carcasses, others, lights, info = build_scene(rng, args.size, args.spp, args.threads,
                                                       blender_seed)
    t_build = time.time() - t0
    jpg = os.path.join(img_dir, name + ".jpg")
    sc.render.filepath = jpg
    t1 = time.time()
    bpy.ops.render.render(write_still=True)
    strip_jpeg_metadata(jpg)
    t_render = time.time() - t1
    exr = os.path.join(tmp_dir, name + "_id.exr")
    t2 = time.time()
    ids = render_id_mask(sc, carcasses, others, lights, exr)
    os.remove(exr)
    t_mask = time.time() - t2
    h, w = ids.shape
    anns = []
    dropped = 0
    for i in range(len(carcasses)):
        m = ids == (i + 1)
        if m.sum() < MIN_PIXELS:
            dropped += int(m.any())
            continue
        rle = mask_util.encode(np.asfortranarray(m.astype(np.uint8)))
        area = float(mask_util.area(rle))
        bbox = [float(x) for x in mask_util.toBbox(rle)]
        rle["counts"] = rle["counts"].decode("ascii")
        anns.append({"segmentation": rle, "area": area, "bbox": bbox, "iscrowd": 0,
                     "category_id": 1})
    info.update(n_visible=len(anns), n_dropped_small=dropped, build_s=round(t_build, 2),
                render_s=round(t_render, 2), mask_s=round(t_mask, 2),
                total_s=round(time.time() - t0, 2))
    side = {"image": {"id": k + 1, "file_name": name + ".jpg", "width": w, "height": h},
            "annotations": anns, "info": info}
    tmp = os.path.join(side_dir, name + ".json.tmp")
    with open(tmp, "w") as f:
        json.dump(side, f)
    os.replace(tmp, os.path.join(side_dir, name + ".json"))
    log(f"[{name}] {len(anns)} instances ({info['n_dropped']} dropped in, {dropped} tiny), "
        f"{info['surface']}, build {t_build:.1f}s (sim {info['sim_s']}s), render {t_render:.1f}s, "
        f"mask {t_mask:.1f}s, total {info['total_s']:.1f}s")


def write_coco(args, side_dir):
    images, anns = [], []
    for k in range(args.count):
        p = os.path.join(side_dir, f"xd_{k:05d}.json")
        if not os.path.exists(p):
            continue
        with open(p) as f:
            side = json.load(f)
        images.append(side["image"])
        for a in side["annotations"]:
            a = dict(a, id=len(anns) + 1, image_id=side["image"]["id"])
            anns.append(a)
    coco = {
        "info": {"description": "chicktrain cross-domain validation set (Blender Cycles, "
                                "own carcass model, rigid-body piles); measurement only",
                 "version": "1.0", "seed": args.seed, "size": args.size, "spp": args.spp},
        "licenses": [],
        "images": images,
        "annotations": anns,
        "categories": [{"id": 1, "name": "carcass", "supercategory": "carcass"}],
    }
    out = os.path.join(args.out, "annotations.json")
    with open(out + ".tmp", "w") as f:
        json.dump(coco, f, separators=(",", ":"))
    os.replace(out + ".tmp", out)
    log(f"wrote {out}: {len(images)} images, {len(anns)} instances")


def main():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--count", type=int, default=100)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--start", type=int, default=0, help="first image index (for testing)")
    args = ap.parse_args(argv)
    img_dir = os.path.join(args.out, "images")
    side_dir = os.path.join(args.out, "sidecars")
    tmp_dir = os.path.join(args.out, "tmp")
    for d in (img_dir, side_dir, tmp_dir):
        os.makedirs(d, exist_ok=True)
    for k in range(args.start, args.count):
        name = f"xd_{k:05d}"
        if (os.path.exists(os.path.join(side_dir, name + ".json"))
                and os.path.exists(os.path.join(img_dir, name + ".jpg"))):
            continue
        render_one(k, args, img_dir, side_dir, tmp_dir)
    write_coco(args, side_dir)
    try:
        os.rmdir(tmp_dir)
    except OSError:
        pass


if __name__ == "__main__":
    main()
