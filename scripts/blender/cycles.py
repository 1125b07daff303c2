"""Blender Cycles on moirecast's device.stl with moirecast render's camera
and light (METHOD §8), then the comparison. Run by scripts/blender-compare.sh:

    blender -b --factory-startup -noaudio -P scripts/blender/cycles.py -- OUT SIZE TILT INDEX SAMPLES [PLUS_X MINUS_X]

PLUS_X and MINUS_X are the lateral lights' linear colours as r,g,b (default
1,1,1 and 0,0,0: moirecast's `--lights white`).

OUT holds device/device.stl, ours-<spp>-<seed>/frame-00.png (the path
tracer) and default-<seed>/frame-00.png (the default integrator) with their
logs; this writes cycles-<seed>.png (and cycles-target-<seed>.png, at the
samples that reach σ = 0.005) and prints the comparison as JSON.
"""
import json
import math
import pathlib
import sys
import time

import bpy
import numpy as np
from mathutils import Matrix, Vector

args = sys.argv[sys.argv.index("--") + 1 :]
out, size, tilt, index, samples = args[:5]
out, size, tilt, index, samples = pathlib.Path(out), int(size), float(tilt), float(index), int(samples)
colour = lambda text: tuple(float(v) for v in text.split(","))
plus_x, minus_x = (colour(args[5]), colour(args[6])) if len(args) > 6 else ((1, 1, 1), (0, 0, 0))
LIGHT_EDGE = 0.15  # moirecast_render::frame::LIGHT_EDGE

scene = bpy.context.scene
for o in list(bpy.data.objects):
    bpy.data.objects.remove(o, do_unlink=True)

# the device, in mm as written
bpy.ops.import_mesh.stl(filepath=str(out / "device" / "device.stl"))
device = bpy.context.selected_objects[0]
glass = bpy.data.materials.new("glass")
glass.use_nodes = True
nodes = glass.node_tree.nodes
nodes.clear()
bsdf = nodes.new("ShaderNodeBsdfGlass")
bsdf.distribution = "SHARP"
bsdf.inputs["IOR"].default_value = index
bsdf.inputs["Color"].default_value = (1, 1, 1, 1)
mat_out = nodes.new("ShaderNodeOutputMaterial")
glass.node_tree.links.new(bsdf.outputs["BSDF"], mat_out.inputs["Surface"])
device.data.materials.append(glass)

# the lateral lights: directions leaving downwards see plus_x towards +x and
# minus_x towards -x, blended over a soft edge; nothing above
# (moirecast_render::frame::Lighting::Lateral)
world = bpy.data.worlds.new("lateral")
scene.world = world
world.use_nodes = True
wn, wl = world.node_tree.nodes, world.node_tree.links
wn.clear()
coords = wn.new("ShaderNodeTexCoord")
xyz = wn.new("ShaderNodeSeparateXYZ")
wl.new(coords.outputs["Generated"], xyz.inputs["Vector"])
ramp = wn.new("ShaderNodeMath")
ramp.operation = "MULTIPLY_ADD"
ramp.use_clamp = True
ramp.inputs[1].default_value = 0.5 / LIGHT_EDGE
ramp.inputs[2].default_value = 0.5
wl.new(xyz.outputs["X"], ramp.inputs[0])
below = wn.new("ShaderNodeMath")
below.operation = "LESS_THAN"
below.inputs[1].default_value = 0.0
wl.new(xyz.outputs["Z"], below.inputs[0])
mix = wn.new("ShaderNodeMixRGB")
mix.blend_type = "MIX"
mix.inputs["Color1"].default_value = (*minus_x, 1)
mix.inputs["Color2"].default_value = (*plus_x, 1)
wl.new(ramp.outputs["Value"], mix.inputs["Fac"])
bg = wn.new("ShaderNodeBackground")
wl.new(mix.outputs["Color"], bg.inputs["Color"])
wl.new(below.outputs["Value"], bg.inputs["Strength"])
w_out = wn.new("ShaderNodeOutputWorld")
wl.new(bg.outputs["Background"], w_out.inputs["Surface"])

# the camera: orthographic, looking down −z tilted about y, the frame the
# device's larger xy extent (moirecast_render::frame::render)
corners = [device.matrix_world @ Vector(c) for c in device.bound_box]
lo = Vector([min(c[i] for c in corners) for i in range(3)])
hi = Vector([max(c[i] for c in corners) for i in range(3)])
centre, extent = (lo + hi) / 2, max(hi.x - lo.x, hi.y - lo.y)
rot = Matrix.Rotation(math.radians(tilt), 4, "Y")
direction = (rot @ Vector((0, 0, -1, 0))).xyz
cam_data = bpy.data.cameras.new("camera")
cam_data.type = "ORTHO"
cam_data.ortho_scale = extent
cam_data.clip_start = 0.01
cam_data.clip_end = 10 * ((hi - lo).length + 1)
camera = bpy.data.objects.new("camera", cam_data)
scene.collection.objects.link(camera)
camera.matrix_world = Matrix.Translation(centre - ((hi - lo).length + 1) * direction) @ rot
scene.camera = camera

scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = samples
scene.cycles.use_adaptive_sampling = False
scene.cycles.use_denoising = False
scene.cycles.max_bounces = 32
scene.cycles.transmission_bounces = 32
scene.cycles.glossy_bounces = 32
scene.cycles.transparent_max_bounces = 32
scene.cycles.caustics_reflective = True
scene.cycles.caustics_refractive = True
scene.cycles.blur_glossy = 0.0
scene.cycles.sample_clamp_direct = 0.0
scene.cycles.sample_clamp_indirect = 0.0
scene.cycles.pixel_filter_type = "BOX"  # as moirecast: samples within the pixel, equal weights
scene.cycles.filter_width = 1.0
scene.render.threads_mode = "FIXED"
scene.render.threads = 2
scene.render.resolution_x = scene.render.resolution_y = size
scene.render.resolution_percentage = 100
scene.render.image_settings.file_format = "PNG"
scene.render.image_settings.color_mode = "RGB"
scene.render.image_settings.color_depth = "16"
scene.display_settings.display_device = "None"  # linear values, as moirecast writes
scene.view_settings.view_transform = "Standard"

def render_cycles(name, seed, spp):
    scene.cycles.seed = seed
    scene.cycles.samples = spp
    scene.render.filepath = str(out / name)
    t = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    return time.perf_counter() - t


times = [render_cycles(f"cycles-{seed}.png", seed, samples) for seed in (1, 2)]


def rgb(path):
    """Linear R, G, B planes, shape (3, h, w) (grey images give three equal planes)."""
    img = bpy.data.images.load(str(path))
    img.colorspace_settings.name = "Non-Color"
    px = np.array(img.pixels[:], dtype=np.float64).reshape(img.size[1], img.size[0], img.channels)
    return np.moveaxis(px[::-1, :, :3], 2, 0)  # Blender's rows run bottom-up


def noise(a, b):
    return float(np.std(a - b) / math.sqrt(2))


def box(img, k):
    """Mean over a k × k box (one lens period): the scale the moiré lives at."""
    if img.ndim == 3:
        return np.stack([box(plane, k) for plane in img])
    k = max(1, int(round(k)))
    c = np.cumsum(np.cumsum(np.pad(img, ((1, 0), (1, 0))), 0), 1)
    h, w = img.shape
    ys, xs = np.arange(h), np.arange(w)
    y0, y1 = np.clip(ys - k // 2, 0, h), np.clip(ys + k - k // 2, 0, h)
    x0, x1 = np.clip(xs - k // 2, 0, w), np.clip(xs + k - k // 2, 0, w)
    s = c[y1][:, x1] - c[y0][:, x1] - c[y1][:, x0] + c[y0][:, x0]
    return s / np.outer(y1 - y0, x1 - x0)


def luminance(planes):
    """Mean Rec. 709 luminance of linear R, G, B planes."""
    return float(np.tensordot([0.2126, 0.7152, 0.0722], planes, 1).mean())


def rendering_ms(log):
    """The time of the `rendering` stage in a `moirecast render -v` log."""
    return [float(l.split()[-2]) for l in log.read_text().splitlines() if l.strip().startswith("rendering")][0]


cycles = [rgb(out / f"cycles-{s}.png") for s in (1, 2)]
ours = {}
for d in sorted(out.glob("ours-*-1")):
    spp = int(d.name.split("-")[1])
    a, b = rgb(d / "frame-00.png"), rgb(out / f"ours-{spp}-2" / "frame-00.png")
    report = json.loads((d / "report.json").read_text())
    ours[spp] = dict(noise=noise(a, b), ms=rendering_ms(d.parent / f"ours-{spp}-1.log"), mean=(a + b) / 2, period_px=report["pixels_per_period"])
c_noise, c_ms = noise(*cycles), 1e3 * min(times)
c_mean = (cycles[0] + cycles[1]) / 2
best = max(ours)
period = ours[best]["period_px"]
# equal noise: noise falls as 1/sqrt(samples); time = fixed + per-sample cost
spps = sorted(ours)
# least squares of time against samples per pixel: BVH and set-up, then per sample
per_sample, fixed = np.polyfit([s * s for s in spps], [ours[s]["ms"] for s in spps], 1)
samples_eq = spps[-1] ** 2 * (ours[spps[-1]]["noise"] / c_noise) ** 2
ours_eq_ms = fixed + per_sample * samples_eq
# the default: no noise. Cycles rendered at the samples its noise at
# `samples` says reach σ = 0.005 (noise falls as 1/sqrt(samples)), twice,
# for its time and its measured noise there
TARGET_NOISE = 0.005
d1, d2 = rgb(out / "default-1" / "frame-00.png"), rgb(out / "default-2" / "frame-00.png")
default_ms = rendering_ms(out / "default-1.log")
c_samples_at_target = math.ceil(samples * (c_noise / TARGET_NOISE) ** 2)
target_times = [render_cycles(f"cycles-target-{seed}.png", seed, c_samples_at_target) for seed in (4, 5)]
c_target_noise = noise(*[rgb(out / f"cycles-target-{seed}.png") for seed in (4, 5)])
c_ms_at_target = 1e3 * min(target_times)
default = dict(
    ms=default_ms,
    noise=noise(d1, d2),
    cycles_samples_for_noise_0005=c_samples_at_target,
    cycles_noise_there=c_target_noise,
    cycles_ms_there=c_ms_at_target,
    time_ratio_cycles_over_ours=c_ms_at_target / default_ms,
    correlation=float(np.corrcoef(c_mean.ravel(), d1.ravel())[0, 1]),
    correlation_one_period=float(np.corrcoef(box(c_mean, period).ravel(), box(d1, period).ravel())[0, 1]),
    mean_luminance=luminance(d1),
)
result = dict(
    size=size,
    tilt_deg=tilt,
    cycles_samples=samples,
    cycles_ms=c_ms,
    cycles_noise=c_noise,
    path={f"{s * s} spp": dict(ms=o["ms"], noise=o["noise"]) for s, o in sorted(ours.items())},
    path_fixed_ms=float(fixed),
    path_ms_per_sample_per_pixel=float(per_sample),
    path_samples_at_cycles_noise=samples_eq,
    path_ms_at_cycles_noise=float(ours_eq_ms),
    time_ratio_cycles_over_ours=c_ms / ours_eq_ms,
    correlation=float(np.corrcoef(c_mean.ravel(), ours[best]["mean"].ravel())[0, 1]),
    correlation_one_period=float(np.corrcoef(box(c_mean, period).ravel(), box(ours[best]["mean"], period).ravel())[0, 1]),
    mean_luminance=dict(cycles=luminance(c_mean), ours=luminance(ours[best]["mean"])),
    lights=dict(plus_x=plus_x, minus_x=minus_x),
    default=default,
)
print("COMPARISON " + json.dumps(result))
