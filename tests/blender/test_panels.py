# SPDX-License-Identifier: GPL-3.0-or-later
"""Panels draw what they should, in every state, against the recording layout.

The first tests check the recorder itself (it must catch what Blender would reject);
the rest draw ProcLoco's own panels.
"""

from __future__ import annotations

from typing import Any

import bpy
import pytest

from procloco_addon.blender.gait import handler
from procloco_addon.blender.gait import panel as gait_panel
from procloco_addon.blender.ui import main
from tests.blender.test_gait_presets import SHIPPED, make_rig
from tests.blender.ui_recorder import (
    RecordingLayout,
    UIRecorderError,
    draw_menu,
    draw_panel,
    draw_panel_header,
)

# -- the recorder ------------------------------------------------------------------------


class _SamplePanel:
    """A draw method touching rows, columns, boxes, sub-panels, props, operators, labels."""

    def draw(self, context: Any) -> None:
        layout = self.layout  # type: ignore[attr-defined]
        layout.use_property_split = True
        col = layout.column(align=True)
        col.prop(context.scene, "frame_start", text="Start")
        col.prop(context.scene, "frame_end")
        box = layout.box()
        row = box.row()
        row.enabled = False
        props = row.operator("render.render", text="Render", icon="RENDER_STILL")
        props.animation = True
        box.label(text="Hello", icon="INFO")
        header, body = layout.panel("sample_sub", default_closed=True)
        header.label(text="More")
        if body is not None:
            body.prop(context.scene.render, "fps")
        self.helper(layout)  # type: ignore[attr-defined]

    def helper(self, layout: Any) -> None:
        layout.menu("TOPBAR_MT_file")


def test_recorder_records_the_tree(empty_scene: Any) -> None:
    ui = draw_panel(_SamplePanel, bpy.context)
    assert ui.attrs["use_property_split"] is True
    assert ui.prop_names() == ["frame_start", "frame_end", "fps"]
    assert ui.has_prop("frame_start", data=empty_scene)
    assert not ui.has_prop("fps", data=empty_scene)  # fps belongs to scene.render
    assert ui.prop_call("frame_start").text == "Start"
    assert ui.operators() == ["render.render"]
    call = ui.operator_calls("render.render")[0]
    assert call.operator_properties == {"animation": True}
    assert call.enabled is False  # drawn inside a disabled row
    assert ui.prop_call("frame_end").enabled is True
    assert ui.labels() == ["Hello", "More"]
    assert ui.menus() == ["TOPBAR_MT_file"]
    assert [c.method for c in ui.calls] == ["column", "box", "panel", "menu"]
    box = ui.calls[1].result
    assert isinstance(box, RecordingLayout)
    assert box.kind == "box"
    assert [c.method for c in box.calls] == ["row", "label"]
    assert "Hello" in ui.texts()
    assert "render.render" in ui.dump()


def test_recorder_draws_closed_sub_panels(empty_scene: Any) -> None:
    ui = draw_panel(_SamplePanel, bpy.context, panels_open=False)
    assert not ui.has_prop("fps")
    assert ui.labels() == ["Hello", "More"]


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda lay, sc: lay.prop(sc, "frame_begin"), "no property 'frame_begin'"),
        (lambda lay, sc: lay.prop(sc, "frame_start", txt="x"), "unexpected keyword 'txt'"),
        (lambda lay, sc: lay.label(text="x", icon="NOT_AN_ICON"), "icon"),
        (lambda lay, sc: lay.label(text=None), "expects a str"),
        (lambda lay, sc: lay.operator("procloco.no_such_thing"), "not registered"),
        (lambda lay, sc: setattr(lay.operator("render.render"), "animaton", True), "no property 'animaton'"),
        (lambda lay, sc: lay.menu("PROCLOCO_MT_missing"), "not registered"),
        (lambda lay, sc: setattr(lay, "alignment", "MIDDLE"), "alignment"),
        (lambda lay, sc: setattr(lay, "enable", False), "no attribute 'enable'"),
        (lambda lay, sc: lay.template_list("UI_UL_list", "x", sc, "legs", sc, "frame_start"),
         "no property 'legs'"),
        (lambda lay, sc: lay.row(True, "head", "ctxt", True, "extra"), "too many"),
        (lambda lay, sc: lay.prop(sc, '["missing"]'), "no custom property"),
    ],
)
def test_recorder_rejects_what_blender_rejects(empty_scene: Any, call: Any, message: str) -> None:
    with pytest.raises(UIRecorderError, match=message):
        call(RecordingLayout(), empty_scene)


def test_recorder_unknown_layout_method_raises(empty_scene: Any) -> None:
    with pytest.raises(AttributeError):
        RecordingLayout().no_such_template()


# -- ProcLoco's panels --------------------------------------------------------------------


def procloco_panels() -> list[type]:
    """Every registered panel of the ProcLoco tab (whoever owns it)."""
    found: list[type] = []
    stack = list(bpy.types.Panel.__subclasses__())
    while stack:
        cls = stack.pop()
        stack.extend(cls.__subclasses__())
        if getattr(cls, "bl_category", "") == "ProcLoco" and getattr(cls, "is_registered", False):
            found.append(cls)
    return sorted(set(found), key=lambda c: c.__name__)


def _state_no_object(scene: Any) -> None:
    bpy.context.view_layer.objects.active = None


def _state_mesh(scene: Any) -> None:
    mesh = bpy.data.objects.new("Ground", bpy.data.meshes.new("Ground"))
    scene.collection.objects.link(mesh)
    bpy.context.view_layer.objects.active = mesh


def _state_rig_without_legs(scene: Any) -> None:
    make_rig(scene, detect=False)


def _state_rig(scene: Any) -> None:
    make_rig(scene)


def _state_rig_overlay_on(scene: Any) -> None:
    make_rig(scene)
    bpy.context.window_manager.procloco_gait_view.show_overlay = True


def _state_two_rigs(scene: Any) -> None:
    make_rig(scene, name="Second")
    make_rig(scene, name="First")  # active, both selected


STATES = {
    "no_object": _state_no_object,
    "mesh": _state_mesh,
    "rig_without_legs": _state_rig_without_legs,
    "rig": _state_rig,
    "rig_overlay_on": _state_rig_overlay_on,
    "two_rigs": _state_two_rigs,
}


@pytest.fixture
def gait_view_reset() -> Any:
    yield
    bpy.context.window_manager.procloco_gait_view.show_overlay = False


def test_the_tab_has_one_parent_and_every_panel_hangs_from_it(empty_scene: Any) -> None:
    panels = procloco_panels()
    names = {cls.__name__ for cls in panels}
    assert {"PROCLOCO_PT_main", "PROCLOCO_PT_gait", "PROCLOCO_PT_effects", "PROCLOCO_PT_generate"} <= names
    roots = [cls for cls in panels if not getattr(cls, "bl_parent_id", "")]
    assert [cls.__name__ for cls in roots] == ["PROCLOCO_PT_main"]
    for cls in panels:
        assert cls.bl_space_type == "VIEW_3D"
        assert cls.bl_region_type == "UI"
        if cls not in roots:
            assert cls.bl_parent_id in names, cls.__name__
    order = {cls.__name__: getattr(cls, "bl_order", 0) for cls in panels}
    assert order["PROCLOCO_PT_gait"] < order["PROCLOCO_PT_effects"] < order["PROCLOCO_PT_generate"]


@pytest.mark.parametrize("state", sorted(STATES))
def test_every_panel_draws_in_every_state(empty_scene: Any, gait_view_reset: Any, state: str) -> None:
    """Each panel of the tab (any owner) polls, and draws only valid calls when it polls."""
    STATES[state](empty_scene)
    drawn = []
    for cls in procloco_panels():
        poll = getattr(cls, "poll", None)
        if poll is not None and not poll(bpy.context):
            continue
        if hasattr(cls, "draw_header"):
            draw_panel_header(cls, bpy.context)
        for panels_open in (True, False):
            ui = draw_panel(cls, bpy.context, panels_open=panels_open)
            assert list(ui.walk()), f"{cls.__name__} drew nothing in state {state}"
        drawn.append(cls.__name__)
    assert "PROCLOCO_PT_main" in drawn
    rig_states = {"rig", "rig_overlay_on", "two_rigs", "rig_without_legs"}
    assert ("PROCLOCO_PT_gait" in drawn) == (state in rig_states)


def test_main_panel_says_what_to_select(empty_scene: Any) -> None:
    ui = draw_panel(main.PROCLOCO_PT_main)
    assert ui.labels() == ["Select an armature to animate"]
    _state_mesh(empty_scene)
    ui = draw_panel(main.PROCLOCO_PT_main)
    assert "Ground is not an armature" in ui.labels()
    _state_two_rigs(empty_scene)
    ui = draw_panel(main.PROCLOCO_PT_main)
    assert ui.labels() == ["First", "+1 selected rig"]


def test_gait_panel_shows_picture_presets_and_every_leg(empty_scene: Any, gait_view_reset: Any) -> None:
    obj = make_rig(empty_scene, n_pairs=3)
    bpy.ops.procloco.apply_gait_preset(filepath=str(SHIPPED / "hexapod_tripod.json"))
    ui = draw_panel(gait_panel.PROCLOCO_PT_gait)
    menu = ui.find("menu", menu="PROCLOCO_MT_gait_presets")
    assert [c.text for c in menu] == ["Hexapod tripod"]  # names the preset applied last
    assert ui.has_operator("procloco.add_gait_preset")
    picture = ui.find("template_icon")
    assert len(picture) == 1
    assert picture[0].params["icon_value"] == handler.icon_id()
    view = bpy.context.window_manager.procloco_gait_view
    assert picture[0].params["scale"] == pytest.approx(view.picture_scale)
    assert ui.has_prop("cycle_time", data=obj.procloco)
    for leg in obj.procloco.legs:
        assert ui.has_prop("swing_start", data=leg), leg.label
        assert ui.has_prop("swing_duration", data=leg), leg.label
        assert leg.label in ui.labels()
    assert ui.has_prop("show_overlay", data=view)
    assert not ui.has_prop("overlay_corner")  # only once the overlay is on
    # Frame 1 of a tripod starting at phase 0: L1, R2, L3 swing.
    assert any("swinging L1, R2, L3" in text for text in ui.labels())

    view.show_overlay = True
    ui = draw_panel(gait_panel.PROCLOCO_PT_gait)
    assert ui.has_prop("overlay_corner", data=view)
    assert ui.has_prop("overlay_cell", data=view)
    assert ui.has_operator("procloco.edit_gait_overlay")


def test_gait_panel_without_legs_points_to_detection(empty_scene: Any) -> None:
    make_rig(empty_scene, detect=False)
    ui = draw_panel(gait_panel.PROCLOCO_PT_gait)
    assert any("detect" in text for text in ui.labels())
    assert not ui.find("template_icon")
    assert ui.menus() == ["PROCLOCO_MT_gait_presets"]


def test_effects_panel_shows_every_effect_switch(empty_scene: Any) -> None:
    obj = make_rig(empty_scene)
    ui = draw_panel(main.PROCLOCO_PT_effects)
    available = [n for n, _ in main.EFFECTS if obj.procloco.bl_rna.properties.get(n) is not None]
    assert available, "the rig settings have no effect switches"
    assert ui.prop_names() == available
    assert all(d == obj.procloco for d, _ in ui.shown_properties())


@pytest.fixture
def stand_in_operators() -> Any:
    """Operators of the Generate section that are not registered yet, as stand-ins."""
    made = []
    for idname, label, _icon in main.GENERATE_OPERATORS:
        if main.operator_available(idname):
            continue
        cls = type(f"PROCLOCO_OT_standin_{idname.split('.')[1]}", (bpy.types.Operator,),
                   {"bl_idname": idname, "bl_label": label, "execute": lambda self, ctx: {"FINISHED"}})
        bpy.utils.register_class(cls)
        made.append(cls)
    yield
    for cls in made:
        bpy.utils.unregister_class(cls)


def test_generate_panel_offers_the_operators(empty_scene: Any, stand_in_operators: Any) -> None:
    _state_two_rigs(empty_scene)
    ui = draw_panel(main.PROCLOCO_PT_generate)
    # ... then Live Preview's Discard beside its toggle
    assert ui.operators() == [*(op for op, _label, _icon in main.GENERATE_OPERATORS),
                              "procloco.discard_live_preview"]
    first = ui.operator_calls("procloco.generate_locomotion")[0]
    assert first.text == "Generate Locomotion (2 rigs)"
    assert first.layout.scale_y > 1.0  # the main button stands out


def test_generate_panel_without_operators_says_so(empty_scene: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(main, "operator_available", lambda _idname: False)
    ui = draw_panel(main.PROCLOCO_PT_generate)
    assert ui.operators() == []
    assert any("not available" in text for text in ui.labels())


def test_every_operator_is_in_the_procloco_menu_for_f3_search(empty_scene: Any) -> None:
    """Blender's F3 search finds operators through menus: each of ProcLoco's operators is
    drawn by the ProcLoco menu (Object/Pose > Animation > ProcLoco), by its Lists submenu or
    by a menu that one of them opens, and that menu hangs in Blender's Animation menu."""
    from procloco_addon.blender import registration
    from procloco_addon.blender.ui import menu

    make_rig(empty_scene)
    operators = {cls.bl_idname for cls in registration.CLASSES if issubclass(cls, bpy.types.Operator)}
    drawn: set[str] = set()
    opened = {menu.PROCLOCO_MT_animation.bl_idname}
    todo = [menu.PROCLOCO_MT_animation]
    while todo:
        ui = draw_menu(todo.pop(), bpy.context)
        drawn |= set(ui.operators())
        for name in ui.menus():
            if name not in opened:
                opened.add(name)
                todo.append(getattr(bpy.types, name))
    via = menu.PROCLOCO_MT_animation.VIA_SUBMENUS
    missing = {op for op in operators - drawn if via.get(op) not in opened}
    assert missing == set(), missing
    assert menu.PROCLOCO_MT_lists.bl_idname in opened
    host = getattr(bpy.types, menu.HOST_MENU)
    assert menu._draw_entry in getattr(host.draw, "_draw_funcs", [])


def test_ui_only_toggles_push_no_undo_step() -> None:
    """Showing the gait circles in the viewport is a display setting: it is not undone."""
    from procloco_addon.blender.gait import ops

    assert "UNDO" not in ops.PROCLOCO_OT_toggle_gait_overlay.bl_options
    assert "UNDO" in ops.PROCLOCO_OT_edit_gait_overlay.bl_options  # editing changes the gait
