# SPDX-License-Identifier: GPL-3.0-or-later
"""The example creatures, terrain and scene built by ``tools/examples`` and
``tools/build_examples.py`` (which writes ``examples.blend``)."""

from __future__ import annotations

import itertools
import json
from pathlib import Path
from typing import Any

import bpy
import numpy as np
import pytest
from bpy_extras.object_utils import world_to_camera_view
from mathutils import Euler

from procloco_addon.blender.cli import image_pixels
from tests.blender.pose_eval import object_world_matrices
from tools.examples import creatures, procloco_props, scene, terrain

KINDS = tuple(creatures.BUILDERS)
N_LEGS = {"spider": 8, "ant": 6, "robot": 5, "lizard": 4, "wolf": 4, "human": 2}


def _world_points(arm: bpy.types.Object, chain: tuple[str, ...]) -> np.ndarray:
    """Rest head of every bone of ``chain`` and the last tail, in world space: ``(len + 1, 3)``."""
    m = np.array(arm.matrix_world)
    bones = arm.data.bones
    local = np.array([bones[n].head_local for n in chain] + [bones[chain[-1]].tail_local])
    return local @ m[:3, :3].T + m[:3, 3]


def _evaluated_vertices(obj: bpy.types.Object) -> np.ndarray:
    depsgraph = bpy.context.evaluated_depsgraph_get()
    evaluated = obj.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    co = np.empty(len(mesh.vertices) * 3)
    mesh.vertices.foreach_get("co", co)
    evaluated.to_mesh_clear()
    return co.reshape(-1, 3)


def _group_of_each_vertex(skin: bpy.types.Object) -> np.ndarray:
    """Index of the one vertex group of each vertex; fails if a vertex has no or several groups."""
    out = np.full(len(skin.data.vertices), -1)
    for v in skin.data.vertices:
        assert len(v.groups) == 1, f"vertex {v.index} is in {len(v.groups)} groups"
        assert v.groups[0].weight == pytest.approx(1.0)
        out[v.index] = v.groups[0].group
    return out


@pytest.mark.parametrize("kind", KINDS)
def test_creature_has_its_leg_chains_standing_on_the_ground(empty_scene: Any, kind: str) -> None:
    location = np.array([1.5, -2.0, 0.25])
    scale = 2.0
    arm = creatures.BUILDERS[kind](empty_scene, location=tuple(location), scale=scale)
    bones = arm.data.bones
    assert arm.type == "ARMATURE"
    assert tuple(arm.scale) == pytest.approx((1.0, 1.0, 1.0))  # scale goes into the bones
    roots = [b.name for b in bones if b.parent is None]
    assert roots == [creatures.ROOT_BONE[kind]]

    chains = creatures.LEG_CHAINS[kind]
    assert len(chains) == N_LEGS[kind]
    lowest = []
    for chain, body in zip(chains, creatures.BODY_BONE[kind], strict=True):
        assert bones[chain[0]].parent.name == body
        for parent, child in itertools.pairwise(chain):
            assert bones[child].parent.name == parent, f"{child} should hang from {parent}"
        # The body bone leads to the root through parents.
        ancestors = []
        b = bones[body]
        while b is not None:
            ancestors.append(b.name)
            b = b.parent
        assert ancestors[-1] == creatures.ROOT_BONE[kind]
        points = _world_points(arm, chain)
        side = chain[0][-2:]
        if side == ".L":
            assert np.all(points[:, 0] > location[0]), f"{chain[0]} is not on the left (+X)"
        elif side == ".R":
            assert np.all(points[:, 0] < location[0]), f"{chain[0]} is not on the right (-X)"
        else:
            np.testing.assert_allclose(points[:, 0], location[0], atol=1e-6)
        # The foot is the lowest point; nothing of the leg is under the ground.
        # (The human's toe lies flat: its tip is as low as the ball of the foot.)
        assert points[-1, 2] <= points[:, 2].min() + 1e-6
        lowest.append(points[-1, 2])
    lowest_arr = np.array(lowest)
    if kind == "human":  # Rigify's human metarig keeps its toes 1.7 cm above its heels' ground
        np.testing.assert_allclose(lowest_arr, location[2] + 0.0167 * scale, atol=2e-3 * scale)
    else:
        np.testing.assert_allclose(lowest_arr, location[2], atol=1e-5)
    # Facing -Y: the front legs' hips are ahead of (lower y than) the hind legs'; a biped's toes point ahead.
    if len(chains) > 2:
        assert _world_points(arm, chains[0])[0, 1] < _world_points(arm, chains[-1])[0, 1]
    else:
        foot = _world_points(arm, chains[0])
        assert foot[-1, 1] < foot[-3, 1] - 0.1 * scale
    # First-click settings, scaled with the creature.
    assert arm.procloco.speed == pytest.approx(creatures.RIG_SETTINGS[kind]["speed"] * scale, rel=1e-6)


@pytest.mark.parametrize("kind", KINDS)
def test_skin_follows_the_armature(empty_scene: Any, kind: str) -> None:
    arm = creatures.BUILDERS[kind](empty_scene, location=(0.3, 0.2, 0.0))
    skin = creatures.skin_of(arm)
    assert skin is not None
    assert skin.parent == arm
    assert skin.data.materials[0].diffuse_color[:3] == pytest.approx(creatures.SKIN_COLORS[kind][:3])
    group = _group_of_each_vertex(skin)
    names = [g.name for g in skin.vertex_groups]
    leg = creatures.LEG_CHAINS[kind][0]
    assert set(leg) <= set(names)
    root = creatures.ROOT_BONE[kind]
    leg_ids = [names.index(n) for n in leg]
    on_leg = np.isin(group, leg_ids)
    on_root = group == names.index(root)
    assert on_leg.any()
    assert on_root.any()

    rest = _evaluated_vertices(skin)
    pose_bone = arm.pose.bones[leg[0]]
    pose_bone.rotation_mode = "XYZ"
    pose_bone.rotation_euler = Euler((0.0, 0.0, 0.7))
    posed = _evaluated_vertices(skin)
    moved = np.linalg.norm(posed - rest, axis=1)
    leg_length = sum(arm.data.bones[n].length for n in leg)
    # The posed leg's skin swings with it; the body's skin stays where it was.
    assert moved[on_leg].max() > 0.2 * leg_length
    assert moved[on_root].max() < 1e-6
    # Unposing gives the rest shape back.
    pose_bone.rotation_euler = Euler((0.0, 0.0, 0.0))
    np.testing.assert_allclose(_evaluated_vertices(skin), rest, atol=1e-6)


@pytest.mark.parametrize("kind", ["wolf", "human"])
def test_metarig_scale_multiplies_every_bone_once(empty_scene: Any, kind: str) -> None:
    """Connected bones share a joint: scaling it once per bone would compound along chains."""
    small = creatures.BUILDERS[kind](empty_scene, name="Small")
    big = creatures.BUILDERS[kind](empty_scene, name="Big", scale=10.0)
    for key in ("head_local", "tail_local"):
        np.testing.assert_allclose(np.array([getattr(b, key) for b in big.data.bones]),
                                   10.0 * np.array([getattr(b, key) for b in small.data.bones]), atol=1e-5)


def test_scale_multiplies_bones_skin_and_settings(empty_scene: Any) -> None:
    small = creatures.build_spider(empty_scene, name="Small")
    big = creatures.build_spider(empty_scene, name="Big", scale=8.0)
    heads_small = np.array([b.head_local for b in small.data.bones])
    heads_big = np.array([b.head_local for b in big.data.bones])
    np.testing.assert_allclose(heads_big, 8.0 * heads_small, atol=1e-6)
    skin_small = creatures.skin_of(small)
    skin_big = creatures.skin_of(big)
    assert skin_small is not None
    assert skin_big is not None
    co_small = np.array([v.co for v in skin_small.data.vertices])
    co_big = np.array([v.co for v in skin_big.data.vertices])
    np.testing.assert_allclose(co_big, 8.0 * co_small, atol=1e-5)
    assert big.procloco.step_height == pytest.approx(8.0 * small.procloco.step_height, rel=1e-6)
    # The tarantula's legs are about 9 cm long at scale 1.
    leg_length = sum(small.data.bones[n].length for n in creatures.LEG_CHAINS["spider"][0])
    assert 0.07 < leg_length < 0.11


def test_terrain_has_ground_crates_stairs_and_gap(empty_scene: Any) -> None:
    built = terrain.build_terrain(empty_scene, frame_start=1, frame_end=48, fps=24)
    ground = built.ground
    mesh = ground.data
    co = np.array([v.co for v in mesh.vertices])
    # The ground is the heightmap, flat where the creatures start, hilly elsewhere.
    np.testing.assert_allclose(co[:, 2], terrain.ground_height(co[:, 0], co[:, 1]), atol=1e-6)
    assert np.all(co[co[:, 1] > 2.0, 2] == 0.0)
    assert np.ptp(co[:, 2]) > 0.5
    for x in terrain.LANE_X.values():
        assert terrain.ground_height(np.array([x]), np.array([terrain.START_Y]))[0] == 0.0
    # A two-material checker, both used.
    material_index = np.array([p.material_index for p in mesh.polygons])
    assert len(mesh.materials) == 2
    assert set(material_index) == {0, 1}
    assert mesh.materials[0].diffuse_color[:3] != pytest.approx(mesh.materials[1].diffuse_color[:3])
    # The gap is a hole in the ground over a trench GAP_DEPTH deep.
    centres = np.array([p.center for p in mesh.polygons])
    x0, x1, y0, y1 = terrain.GAP_RECT
    in_gap = (centres[:, 0] > x0) & (centres[:, 0] < x1) & (centres[:, 1] > y0) & (centres[:, 1] < y1)
    assert not in_gap.any()
    near_gap = (centres[:, 0] > x0) & (centres[:, 0] < x1) & (np.abs(centres[:, 1] - y1) < terrain.CELL)
    assert near_gap.any()
    gap_co = np.array([v.co for v in built.gap.data.vertices])
    assert gap_co[:, 2].min() == pytest.approx(-terrain.GAP_DEPTH)
    assert gap_co[:, 0].min() == pytest.approx(x0)
    assert gap_co[:, 1].max() == pytest.approx(y1)
    # Stairs climb to a landing STAIR_STEPS rises high.
    stairs_co = np.array([v.co for v in built.stairs.data.vertices])
    assert stairs_co[:, 2].max() == pytest.approx(terrain.STAIR_STEPS * terrain.STAIR_RISE)
    assert len({round(z, 4) for z in stairs_co[:, 2]}) == terrain.STAIR_STEPS + 1  # ground + each rise
    # Static crates rest on the ground: no corner of the bottom floats, none is buried deep.
    assert len(built.static_crates) >= 4
    for crate in built.static_crates:
        bottom = np.array([c for c in crate.bound_box if c[2] == 0.0]) + np.array(crate.location)
        under = terrain.ground_height(bottom[:, 0], bottom[:, 1]).min()
        assert under - 0.02 <= crate.location.z <= under + 1e-6
        assert crate.animation_data is None
    # Moving crates are keyed: they move along x, at constant height.
    assert len(built.moving_crates) >= 2
    for crate in built.moving_crates:
        assert crate.animation_data is not None
        assert crate.animation_data.action is not None
        track = object_world_matrices(crate, [1, 13, 25, 37])[:, :3, 3]
        assert np.ptp(track[:, 0]) > 0.3
        np.testing.assert_allclose(track[:, 1:], np.broadcast_to(track[0, 1:], track[:, 1:].shape), atol=1e-6)


def test_terrain_roles(empty_scene: Any) -> None:
    if not procloco_props.role_registered():
        pytest.skip("the add-on does not register Object.procloco_role yet")
    built = terrain.build_terrain(empty_scene, frame_end=10)
    assert built.ground.procloco_role == "GROUND"
    assert built.stairs.procloco_role == "GROUND"
    assert built.gap.procloco_role == "IGNORE"  # the gap is the hole in the ground; this is its look
    roles = {c.procloco_role for c in built.static_crates}
    assert roles == {"STEP_OVER", "AVOID"}
    assert {c.procloco_role for c in built.moving_crates} == {"AVOID"}
    spider = creatures.build_spider(empty_scene)
    skin = creatures.skin_of(spider)
    assert skin is not None
    assert skin.procloco_role == "IGNORE"


def _render_pixels(sc: bpy.types.Scene, path: Path) -> np.ndarray:
    sc.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    return image_pixels(path)[..., :3]  # row 0 is the bottom of the picture


def test_example_scene_render_shows_every_creature(empty_scene: Any, tmp_path: Path) -> None:
    built = scene.build_example_scene(empty_scene)
    assert set(built.rigs) == set(KINDS)
    assert empty_scene.render.engine == "BLENDER_WORKBENCH"
    assert (empty_scene.render.resolution_x, empty_scene.render.resolution_y) == (640, 360)
    empty_scene.render.resolution_x, empty_scene.render.resolution_y = 160, 90
    boxes = scene.creature_screen_boxes(empty_scene, built.rigs)
    with_creatures = _render_pixels(empty_scene, tmp_path / "with.png")
    skins = [creatures.skin_of(rig) for rig in built.rigs.values()]
    for skin in skins:
        assert skin is not None
        skin.hide_render = True
    without = _render_pixels(empty_scene, tmp_path / "without.png")
    changed = np.abs(with_creatures - without).max(axis=2) > 0.05
    h, w = changed.shape
    for kind, (u0, v0, u1, v1) in boxes.items():
        # The whole creature is in the picture...
        assert 0.0 <= u0 < u1 <= 1.0, f"{kind} is not fully in frame"
        assert 0.0 <= v0 < v1 <= 1.0, f"{kind} is not fully in frame"
        # ...and its skin covers pixels inside its projected bounding box.
        region = changed[int(v0 * h):int(np.ceil(v1 * h)), int(u0 * w):int(np.ceil(u1 * w))]
        assert region.sum() >= 4, f"{kind}: only {region.sum()} pixels show the creature"
    # The terrain's features are in the picture too.
    for obj in (built.terrain.stairs, built.terrain.gap, *built.terrain.moving_crates):
        uv = np.array([world_to_camera_view(empty_scene, empty_scene.camera, p)[:2]
                       for p in scene.bound_corners([obj])])
        assert np.all((uv >= 0.0) & (uv <= 1.0)), f"{obj.name} leaves the picture"


def _summary() -> dict[str, Any]:
    """What a saved example file holds: objects, bones, mesh sizes and settings. Floats stay
    unrounded: :func:`_assert_same_summary` compares them to a tolerance (a value rounded to a
    few decimals can sit on a rounding boundary and flip between machines)."""
    out: dict[str, Any] = {}
    for obj in bpy.data.objects:
        entry: dict[str, Any] = {"type": obj.type, "parent": obj.parent.name if obj.parent else None,
                                 "location": tuple(obj.location)}
        if procloco_props.role_registered():
            entry["role"] = obj.procloco_role
        if obj.type == "ARMATURE":
            entry["bones"] = sorted(b.name for b in obj.data.bones)
            entry["speed"] = obj.procloco.speed
        if obj.type == "MESH":
            co = np.array([v.co for v in obj.data.vertices])
            entry["mesh"] = (len(obj.data.vertices), len(obj.data.polygons), float(co.sum()))
            entry["animated"] = obj.animation_data is not None and obj.animation_data.action is not None
        out[obj.name] = entry
    return out


def _assert_same_summary(got: Any, want: Any, where: str = "") -> None:
    """``got`` and ``want`` (nested dicts, tuples, lists) hold the same names, counts and
    settings, and floats within 1e-3 + 1e-6 relative: a vertex sum of float32 coordinates
    over thousands of vertices may move in its last bits between CPUs (numpy's sin and cos
    round differently under different SIMD), a crate moved by a millimetre does not hide."""
    if isinstance(want, float) or isinstance(got, float):
        assert isinstance(got, (int, float)), where
        assert isinstance(want, (int, float)), where
        assert abs(got - want) <= 1e-3 + 1e-6 * abs(want), f"{where}: {got} != {want}"
    elif isinstance(want, dict):
        assert isinstance(got, dict), where
        assert sorted(got) == sorted(want), f"{where}: {sorted(got)} != {sorted(want)}"
        for key in want:
            _assert_same_summary(got[key], want[key], f"{where}/{key}")
    elif isinstance(want, (tuple, list)):
        assert isinstance(got, (tuple, list)), where
        assert len(got) == len(want), f"{where}: {got} != {want}"
        for i, (g, w) in enumerate(zip(got, want, strict=True)):
            _assert_same_summary(g, w, f"{where}[{i}]")
    else:
        assert got == want, f"{where}: {got!r} != {want!r}"


def test_summary_comparison_tolerates_rounding_and_sees_real_changes() -> None:
    want = {"Crate": {"location": (1.0, 2.0, 0.0), "mesh": (8, 6, 12.3445), "bones": ["a", "b"]}}
    # Either side of a 3-decimal rounding boundary (12.3445 -> 12.344 or 12.345): the same file.
    _assert_same_summary({"Crate": {"location": (1.0, 2.0, 0.0), "mesh": (8, 6, 12.34450000001),
                                    "bones": ["a", "b"]}}, want)
    for changed in ({"Crate": {"location": (1.0, 2.002, 0.0), "mesh": (8, 6, 12.3445), "bones": ["a", "b"]}},
                    {"Crate": {"location": (1.0, 2.0, 0.0), "mesh": (9, 6, 12.3445), "bones": ["a", "b"]}},
                    {"Crate": {"location": (1.0, 2.0, 0.0), "mesh": (8, 6, 12.3445), "bones": ["a"]}},
                    {"Box": want["Crate"]}):
        with pytest.raises(AssertionError):
            _assert_same_summary(changed, want)


def test_build_script_is_idempotent_and_the_file_reopens(empty_scene: Any, tmp_path: Path) -> None:
    from tools import build_examples

    first, second = tmp_path / "a.blend", tmp_path / "b.blend"
    build_examples.build(first)
    build_examples.build(second)
    summaries = []
    for path in (first, second):
        bpy.ops.wm.open_mainfile(filepath=str(path))
        summaries.append(_summary())
    _assert_same_summary(summaries[0], summaries[1])
    s = summaries[1]
    armatures = sorted(n for n, e in s.items() if e["type"] == "ARMATURE")
    assert armatures == sorted(scene.CREATURE_NAMES.values())
    for name in armatures:
        assert s[f"{name}_Skin"]["parent"] == name
    assert sum(e.get("animated", False) for e in s.values()) == len(terrain._MOVING_CRATES)
    assert bpy.context.scene.camera is not None
    sc = bpy.context.scene
    assert (sc.frame_start, sc.frame_end) == (scene.FRAME_START, scene.FRAME_END)


def test_committed_examples_blend_matches_the_script(
    empty_scene: Any, repo_root: Path, tmp_path: Path
) -> None:
    committed = repo_root / "examples.blend"
    if not committed.exists():
        pytest.fail("examples.blend is missing: run tools/build_examples.py")
    from tools import build_examples

    fresh = tmp_path / "fresh.blend"
    build_examples.build(fresh)
    bpy.ops.wm.open_mainfile(filepath=str(fresh))
    expected = _summary()
    bpy.ops.wm.open_mainfile(filepath=str(committed))
    try:
        _assert_same_summary(_summary(), expected)
    except AssertionError as err:
        raise AssertionError(f"examples.blend is stale: run tools/build_examples.py ({err})") from None


def test_example_rigs_are_set_up_for_the_first_click(empty_scene: Any) -> None:
    built = scene.build_example_scene(empty_scene)
    terrain_collection = bpy.data.collections["Terrain"]
    assert set(terrain_collection.objects) >= set(built.terrain.all_objects())
    for rig in built.rigs.values():
        settings = rig.procloco
        assert settings.terrain_collection == terrain_collection
        assert settings.use_scene_range
    if not scene._operator_registered("procloco.detect_legs"):
        pytest.skip("the add-on has no Detect Legs operator yet: legs and gait presets are not set")
    for kind, rig in built.rigs.items():
        settings = rig.procloco
        assert len(settings.legs) == N_LEGS[kind], kind
        preset = json.loads((scene.PRESET_DIR / f"{creatures.GAIT_PRESET[kind]}.json").read_text())
        assert settings.gait_preset == preset["name"]
        assert settings.cycle_time == pytest.approx(preset["cycle_time"])
        # Speed and step height come from the preset, both scaled by the rig's leg length.
        assert settings.speed / settings.step_height == pytest.approx(preset["speed"] / preset["step_height"],
                                                                      rel=1e-5)
        by_label = {leg.label: leg for leg in settings.legs}
        for label, start, duration in zip(preset["legs"], preset["swing_start"], preset["swing_duration"],
                                          strict=True):
            assert by_label[label].swing_start == pytest.approx(start)
            assert by_label[label].swing_duration == pytest.approx(duration)
        assert "procloco_pending_settings" not in rig


def test_contact_sheet_has_a_close_up_of_each_creature(empty_scene: Any, tmp_path: Path) -> None:
    built = terrain.build_ground(empty_scene, x_range=(-2.0, 2.0), y_range=(-2.0, 2.0), cell=0.5,
                                 height=lambda x, y: np.zeros_like(x))
    rigs = {"spider": creatures.build_spider(empty_scene, location=(-1.0, 0.0, 0.0), scale=8.0),
            "robot": creatures.build_robot(empty_scene, location=(1.0, 0.0, 0.0))}
    scene.setup_render(empty_scene)
    main_camera = scene.frame_camera(empty_scene, scene.bound_corners([built]))
    before = (empty_scene.camera, empty_scene.render.resolution_x, empty_scene.render.resolution_y)
    n_objects = len(bpy.data.objects)
    path = scene.render_contact_sheet(empty_scene, rigs, tmp_path / "sheet.png", tile=(64, 36), columns=2)
    sheet = scene._read_png(path)[..., :3]
    assert sheet.shape == (36, 128, 3)
    # The same close-ups with the skins hidden: each tile must lose its creature.
    for rig in rigs.values():
        skin = creatures.skin_of(rig)
        assert skin is not None
        skin.hide_render = True
    empty = scene._read_png(scene.render_contact_sheet(empty_scene, rigs, tmp_path / "empty.png",
                                                       tile=(64, 36), columns=2))[..., :3]
    changed = np.abs(sheet - empty).max(axis=2) > 0.05
    for col, kind in enumerate(rigs):
        assert changed[:, col * 64:(col + 1) * 64].mean() > 0.05, f"{kind} is hardly in its close-up"
    # Nothing of the scene changed.
    assert (empty_scene.camera, empty_scene.render.resolution_x, empty_scene.render.resolution_y) == before
    assert empty_scene.camera == main_camera
    assert len(bpy.data.objects) == n_objects


def test_close_ups_leave_out_crates_that_hide_the_creature(empty_scene: Any) -> None:
    terrain.build_ground(empty_scene, x_range=(-3.0, 3.0), y_range=(-3.0, 3.0), cell=0.5,
                         height=lambda x, y: np.zeros_like(x))
    spider = creatures.build_spider(empty_scene, scale=8.0)
    scene.setup_render(empty_scene)
    # A tall crate between the close-up camera and the spider.
    toward_camera = -np.array(scene.CLOSEUP_DIRECTION[:2]) / np.linalg.norm(scene.CLOSEUP_DIRECTION[:2])
    crate = terrain.build_crate(empty_scene, "Crate", tuple(0.9 * toward_camera), (0.3, 0.3, 1.5), "AVOID")
    bpy.context.view_layer.update()
    shots = scene.render_close_ups(empty_scene, {"spider": spider}, tile=(64, 48))["spider"]
    assert not crate.hide_render  # put back
    crate.hide_render = True
    clear = scene.render_close_ups(empty_scene, {"spider": spider}, tile=(64, 48))["spider"]
    np.testing.assert_allclose(shots, clear, atol=1e-3)
    # Beside the creature, out of the way, it stays in the picture.
    crate.hide_render = False
    crate.location = (-0.9 * toward_camera[0], -0.9 * toward_camera[1], 0.0)
    bpy.context.view_layer.update()
    behind = scene.render_close_ups(empty_scene, {"spider": spider}, tile=(64, 48))["spider"]
    assert np.abs(behind - clear).max() > 0.1
