# SPDX-License-Identifier: GPL-3.0-or-later
"""Panels draw what they should, in every state, against the recording layout.

The first tests check the recorder itself (it must catch what Blender would reject);
the rest draw ProcLoco's own panels.
"""

from __future__ import annotations

from typing import Any

import bpy
import pytest

from tests.blender.ui_recorder import (
    RecordingLayout,
    UIRecorderError,
    draw_panel,
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
