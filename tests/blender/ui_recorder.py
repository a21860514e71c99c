# SPDX-License-Identifier: GPL-3.0-or-later
"""A recording stand-in for ``bpy.types.UILayout``, to test ``draw`` methods headless.

A real ``UILayout`` cannot be built without a window, and ``bpy.ops.wm.call_panel``
crashes in background mode, so panel, menu and UI-list ``draw`` code is tested by
calling it with a :class:`RecordingLayout` in place of ``self.layout``. The stand-in
checks every call against Blender's own RNA description of ``UILayout`` (so a typo in
a keyword, an icon name that does not exist, an unknown operator, menu or property
fails the test exactly where Blender would fail or draw an error), and records what
was drawn as a tree that tests can query::

    from tests.blender.ui_recorder import draw_panel

    ui = draw_panel(PROCLOCO_PT_gait, bpy.context)
    assert ui.has_prop("show_overlay")
    assert ui.has_operator("procloco.add_gait_preset")
    assert "Select an armature" in ui.texts()

Everything is checked against the RNA of the running Blender, so the recorder follows
the API of whichever Blender version the tests run on (4.2 LTS or 5.x).
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import bpy

__all__ = [
    "Call",
    "ContextStandIn",
    "RecordedOperator",
    "RecordingLayout",
    "UIRecorderError",
    "draw_menu",
    "draw_panel",
    "draw_panel_header",
    "draw_ui_list_item",
]

# Methods of UILayout that show one property of a data block: (data param, property param).
_PROPERTY_PARAMS: dict[str, tuple[tuple[str, str], ...]] = {
    "prop": (("data", "property"),),
    "props_enum": (("data", "property"),),
    "prop_menu_enum": (("data", "property"),),
    "prop_with_popover": (("data", "property"),),
    "prop_with_menu": (("data", "property"),),
    "prop_tabs_enum": (("data", "property"),),
    "prop_enum": (("data", "property"),),
    "prop_search": (("data", "property"),),
    "prop_decorator": (("data", "property"),),
    "template_ID": (("data", "property"),),
    "template_ID_preview": (("data", "property"),),
    "template_any_ID": (("data", "property"),),
    "template_search": (("data", "property"),),
    "template_search_preview": (("data", "property"),),
    "template_path_builder": (("data", "property"),),
    "template_curve_mapping": (("data", "property"),),
    "template_color_ramp": (("data", "property"),),
    "template_icon_view": (("data", "property"),),
    "template_matrix": (("data", "property"),),
    "template_color_picker": (("data", "property"),),
    "template_layers": (("data", "property"),),
    "template_list": (("dataptr", "propname"), ("active_dataptr", "active_propname")),
    "panel_prop": (("data", "property"),),
}

_OPERATOR_METHODS = {"operator", "operator_menu_hold", "operator_enum", "operator_menu_enum"}


class UIRecorderError(AssertionError):
    """A draw call that Blender would reject or draw as an error."""


def _rna_function(name: str) -> Any:
    func = bpy.types.UILayout.bl_rna.functions.get(name)
    if func is None:
        raise UIRecorderError(f"UILayout has no method {name!r} in Blender {bpy.app.version_string}")
    return func


def _check_value(where: str, param: Any, value: Any) -> None:
    """Type-check one argument the way Blender's RNA would."""
    kind = param.type
    if kind == "POINTER":
        if value is None and param.is_required:
            raise UIRecorderError(f"{where}: {param.identifier} must not be None")
        return
    if kind == "STRING":
        if not isinstance(value, str):
            raise UIRecorderError(f"{where}: {param.identifier} expects a str, got {value!r}")
    elif kind == "BOOLEAN":
        if not isinstance(value, (bool, int)):
            raise UIRecorderError(f"{where}: {param.identifier} expects a bool, got {value!r}")
    elif kind == "INT":
        if isinstance(value, bool) or not isinstance(value, int):
            raise UIRecorderError(f"{where}: {param.identifier} expects an int, got {value!r}")
    elif kind == "FLOAT":
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise UIRecorderError(f"{where}: {param.identifier} expects a number, got {value!r}")
    elif kind == "ENUM":
        items = param.enum_items.keys()
        values = value if param.is_enum_flag else {value}
        bad = [v for v in values if v not in items]
        if bad:
            raise UIRecorderError(f"{where}: {param.identifier}={value!r} is not one of Blender's items")


def _operator_rna(idname: str) -> Any:
    """The RNA type of a registered operator ``"module.name"``, or raise."""
    module, _, name = idname.partition(".")
    if not module or not name:
        raise UIRecorderError(f"operator id {idname!r} is not of the form 'module.name'")
    try:
        return getattr(getattr(bpy.ops, module), name).get_rna_type()
    except (AttributeError, KeyError) as error:
        raise UIRecorderError(f"operator {idname!r} is not registered") from error


def _check_property(where: str, data: Any, name: str) -> None:
    """``name`` must be an RNA property (or an existing ID property) of ``data``."""
    if name.startswith('["'):
        key = name[2:-2]
        try:
            found = key in data
        except TypeError:
            found = False
        if not found:
            raise UIRecorderError(f"{where}: {data!r} has no custom property {key!r}")
        return
    bl_rna = getattr(data, "bl_rna", None)
    if bl_rna is None:
        return  # not an RNA struct (a test double): nothing to check against
    if bl_rna.properties.get(name) is None:
        raise UIRecorderError(f"{where}: {type(data).__name__} has no property {name!r}")


class RecordedOperator:
    """Stands in for the ``OperatorProperties`` a ``layout.operator`` call returns.

    Assigning an attribute checks that the operator has that property and records it in
    :attr:`properties`.
    """

    def __init__(self, idname: str, rna: Any) -> None:
        object.__setattr__(self, "idname", idname)
        object.__setattr__(self, "properties", {})
        object.__setattr__(self, "_names", set(rna.properties.keys()) - {"rna_type"})

    def __setattr__(self, name: str, value: Any) -> None:
        if name not in self._names:
            raise UIRecorderError(f"operator {self.idname!r} has no property {name!r}")
        self.properties[name] = value

    def __getattr__(self, name: str) -> Any:
        props = object.__getattribute__(self, "properties")
        if name in props:
            return props[name]
        raise AttributeError(name)


@dataclass(eq=False)
class Call:
    """One recorded ``UILayout`` call.

    ``params`` holds every argument by its RNA name (positional ones included);
    ``result`` is what the stand-in returned (a child layout, a tuple of them, a
    :class:`RecordedOperator` or None); ``enabled``/``active``/``alert`` are the
    effective states of the layout at the time of the call (ANDed over its parents).
    """

    method: str
    params: dict[str, Any]
    layout: RecordingLayout = field(repr=False)
    result: Any = None
    enabled: bool = True
    active: bool = True
    alert: bool = False

    @property
    def text(self) -> str | None:
        return self.params.get("text")

    @property
    def operator_properties(self) -> dict[str, Any]:
        return self.result.properties if isinstance(self.result, RecordedOperator) else {}

    def shown_properties(self) -> list[tuple[Any, str]]:
        """The (data, property name) pairs this call displays."""
        pairs = _PROPERTY_PARAMS.get(self.method, ())
        return [(self.params.get(d), self.params[p]) for d, p in pairs if p in self.params]


@dataclass(eq=False)
class RecordingLayout:
    """A stand-in for ``bpy.types.UILayout`` that records every call.

    ``kind`` names what created it ("root", "row", "column", "box", "split",
    "panel_header", "panel_body", ...). Layout attributes (``enabled``,
    ``use_property_split``, ``alignment``...) are checked against Blender's RNA and stored.
    ``panels_open`` decides whether ``layout.panel(...)`` returns a body (open) or
    ``None`` (closed), so both states of a collapsible sub-panel can be drawn.
    """

    kind: str = "root"
    parent: RecordingLayout | None = field(default=None, repr=False)
    panels_open: bool = True
    calls: list[Call] = field(default_factory=list)
    attrs: dict[str, Any] = field(default_factory=dict)
    creation_params: dict[str, Any] = field(default_factory=dict)

    # -- layout attributes -------------------------------------------------------------
    def __setattr__(self, name: str, value: Any) -> None:
        if name in RecordingLayout.__dataclass_fields__:
            object.__setattr__(self, name, value)
            return
        prop = bpy.types.UILayout.bl_rna.properties.get(name)
        if prop is None or name == "rna_type":
            raise UIRecorderError(f"UILayout has no attribute {name!r}")
        if prop.is_readonly:
            raise UIRecorderError(f"UILayout.{name} is read-only")
        _check_value(f"layout.{name}", prop, value)
        self.attrs[name] = value

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__"):
            raise AttributeError(name)
        attrs = object.__getattribute__(self, "attrs")
        if name in attrs:
            return attrs[name]
        prop = bpy.types.UILayout.bl_rna.properties.get(name)
        if prop is not None and name != "rna_type":
            return _DEFAULT_ATTRS.get(name, getattr(prop, "default", None))
        func = bpy.types.UILayout.bl_rna.functions.get(name)
        if func is None:
            raise AttributeError(f"UILayout has no attribute {name!r}")
        return lambda *args, **kwargs: self._record(name, func, args, kwargs)

    def _effective(self, attr: str, default: bool) -> bool:
        layout: RecordingLayout | None = self
        value = default
        while layout is not None:
            own = layout.attrs.get(attr, default)
            value = (value and own) if default else (value or own)
            layout = layout.parent
        return value

    # -- recording -----------------------------------------------------------------------
    def _record(self, name: str, func: Any, args: tuple[Any, ...], kwargs: dict[str, Any]) -> Any:
        inputs = [p for p in func.parameters if not p.is_output]
        outputs = [p for p in func.parameters if p.is_output]
        where = f"layout.{name}"
        if len(args) > len(inputs):
            raise UIRecorderError(f"{where}: too many positional arguments")
        params: dict[str, Any] = {}
        for param, value in zip(inputs, args, strict=False):
            params[param.identifier] = value
        by_name = {p.identifier: p for p in inputs}
        for key, value in kwargs.items():
            if key not in by_name:
                raise UIRecorderError(f"{where}: unexpected keyword {key!r}")
            if key in params:
                raise UIRecorderError(f"{where}: {key!r} given twice")
            params[key] = value
        for param in inputs:
            if param.identifier in params:
                _check_value(where, param, params[param.identifier])
            elif param.is_required:
                raise UIRecorderError(f"{where}: missing required argument {param.identifier!r}")
        for data_key, prop_key in _PROPERTY_PARAMS.get(name, ()):
            if prop_key in params and params.get(data_key) is not None:
                _check_property(where, params[data_key], params[prop_key])
        self._check_references(where, name, params)

        call = Call(
            method=name, params=params, layout=self,
            enabled=self._effective("enabled", True), active=self._effective("active", True),
            alert=self._effective("alert", False),
        )
        results: list[Any] = []
        for out in outputs:
            fixed = out.fixed_type.identifier if out.type == "POINTER" else ""
            if fixed == "UILayout":
                child_kind = name if len(outputs) == 1 else f"{name}_{out.identifier.removeprefix('layout_')}"
                closed = not self.panels_open
                if name in {"panel", "panel_prop"} and out.identifier == "layout_body" and closed:
                    results.append(None)
                    continue
                results.append(RecordingLayout(kind=child_kind, parent=self, panels_open=self.panels_open,
                                               creation_params=dict(params)))
            elif fixed == "OperatorProperties":
                results.append(RecordedOperator(params["operator"], _operator_rna(params["operator"])))
            else:
                results.append(None)
        call.result = results[0] if len(results) == 1 else (tuple(results) if results else None)
        self.calls.append(call)
        return call.result

    @staticmethod
    def _check_references(where: str, name: str, params: dict[str, Any]) -> None:
        """Operators, menus and panels named in a call must exist, as Blender would need."""
        if name in _OPERATOR_METHODS:
            rna = _operator_rna(params["operator"])
            prop = params.get("property")
            if prop is not None and rna.properties.get(prop) is None:
                raise UIRecorderError(f"{where}: {params['operator']!r} has no property {prop!r}")
        if name in {"menu", "menu_contents"} and not hasattr(bpy.types, params["menu"]):
            raise UIRecorderError(f"{where}: menu {params['menu']!r} is not registered")
        if name in {"popover", "prop_with_popover"} and not hasattr(bpy.types, params["panel"]):
            raise UIRecorderError(f"{where}: panel {params['panel']!r} is not registered")
        if name == "template_list" and not hasattr(bpy.types, params["listtype_name"]):
            raise UIRecorderError(f"{where}: UI list {params['listtype_name']!r} is not registered")

    # -- queries ---------------------------------------------------------------------------
    def children(self) -> Iterator[RecordingLayout]:
        for call in self.calls:
            results = call.result if isinstance(call.result, tuple) else (call.result,)
            for result in results:
                if isinstance(result, RecordingLayout):
                    yield result

    def walk(self) -> Iterator[Call]:
        """Every call, depth first, in drawing order (a container before its contents)."""
        for call in self.calls:
            yield call
            results = call.result if isinstance(call.result, tuple) else (call.result,)
            for result in results:
                if isinstance(result, RecordingLayout):
                    yield from result.walk()

    def find(self, method: str | None = None, **params: Any) -> list[Call]:
        """Calls of ``method`` (any method if None) whose params include all ``params``."""
        return [
            c for c in self.walk()
            if (method is None or c.method == method)
            and all(k in c.params and c.params[k] == v for k, v in params.items())
        ]

    def shown_properties(self) -> list[tuple[Any, str]]:
        """(data, property name) for every property drawn, in drawing order."""
        return [pair for call in self.walk() for pair in call.shown_properties()]

    def prop_names(self) -> list[str]:
        return [name for _data, name in self.shown_properties()]

    def has_prop(self, name: str, data: Any = None) -> bool:
        """True if property ``name`` (of ``data``, when given) is drawn anywhere."""
        return any(n == name and (data is None or d == data) for d, n in self.shown_properties())

    def prop_call(self, name: str, data: Any = None) -> Call:
        """The first call drawing property ``name`` (of ``data`` when given)."""
        for call in self.walk():
            if any(n == name and (data is None or d == data) for d, n in call.shown_properties()):
                return call
        raise KeyError(f"property {name!r} is not drawn; drawn: {self.prop_names()}")

    def operators(self) -> list[str]:
        return [c.params["operator"] for c in self.walk() if c.method in _OPERATOR_METHODS]

    def has_operator(self, idname: str) -> bool:
        return idname in self.operators()

    def operator_calls(self, idname: str) -> list[Call]:
        return [c for c in self.walk() if c.method in _OPERATOR_METHODS and c.params["operator"] == idname]

    def menus(self) -> list[str]:
        return [c.params["menu"] for c in self.walk() if c.method in {"menu", "menu_contents"}]

    def labels(self) -> list[str]:
        return [c.params.get("text", "") for c in self.walk() if c.method == "label"]

    def texts(self) -> str:
        """Every text shown (labels, button and property text overrides), one per line."""
        return "\n".join(c.params["text"] for c in self.walk() if isinstance(c.params.get("text"), str))

    def dump(self, indent: int = 0) -> str:
        """A readable tree of what was drawn, for assertion messages."""
        lines = []
        for call in self.calls:
            shown = {k: v for k, v in call.params.items() if not hasattr(v, "bl_rna")}
            flags = "" if call.enabled else " [disabled]"
            lines.append(" " * indent + f"{call.method}({shown}){flags}")
            results = call.result if isinstance(call.result, tuple) else (call.result,)
            lines.extend(r.dump(indent + 2) for r in results if isinstance(r, RecordingLayout))
        return "\n".join(line for line in lines if line)


_DEFAULT_ATTRS: dict[str, Any] = {
    "enabled": True, "active": True, "alert": False, "active_default": False, "activate_init": False,
    "scale_x": 1.0, "scale_y": 1.0, "ui_units_x": 0.0, "ui_units_y": 0.0,
    "use_property_split": False, "use_property_decorate": True, "alignment": "EXPAND",
    "operator_context": "INVOKE_REGION_WIN", "emboss": "NORMAL", "direction": "VERTICAL",
}


class _DrawSelf:
    """Stands in for the Panel/Menu/UIList instance Blender would pass as ``self``.

    Registered Blender classes cannot be instantiated from Python; methods of ``cls``
    are bound to this object instead, class attributes are read through, and
    ``layout`` is the recorder.
    """

    def __init__(self, cls: type, layout: RecordingLayout | None, extra: dict[str, Any]) -> None:
        self._cls = cls
        self.layout = layout
        self.__dict__.update(extra)

    def __getattr__(self, name: str) -> Any:
        cls = object.__getattribute__(self, "_cls")
        for klass in cls.__mro__:
            if name in vars(klass):
                raw = vars(klass)[name]
                if isinstance(raw, (classmethod, staticmethod)) or not inspect.isfunction(raw):
                    return getattr(cls, name)
                return raw.__get__(self)
        return getattr(cls, name)


class ContextStandIn:
    """``bpy.context`` with some members replaced (e.g. ``area``, ``region``, ``object``)."""

    def __init__(self, base: Any = None, **overrides: Any) -> None:
        self._base = bpy.context if base is None else base
        self._overrides = overrides

    def __getattr__(self, name: str) -> Any:
        overrides = object.__getattribute__(self, "_overrides")
        if name in overrides:
            return overrides[name]
        return getattr(object.__getattribute__(self, "_base"), name)


def _call_draw(cls: type, method: str, context: Any, layout: RecordingLayout, **extra: Any) -> None:
    draw: Callable[..., Any] = getattr(_DrawSelf(cls, layout, extra), method)
    draw(context)


def draw_panel(cls: type, context: Any = None, *, panels_open: bool = True) -> RecordingLayout:
    """Run ``cls.draw(context)`` (a Panel or Menu subclass) against a fresh recorder.

    Panels that define ``draw_header`` are not drawn by this call; use
    :func:`draw_panel_header` for the header.
    """
    layout = RecordingLayout(kind="root", panels_open=panels_open)
    _call_draw(cls, "draw", bpy.context if context is None else context, layout)
    return layout


def draw_panel_header(cls: type, context: Any = None) -> RecordingLayout:
    """Run ``cls.draw_header(context)`` against a fresh recorder."""
    layout = RecordingLayout(kind="header")
    _call_draw(cls, "draw_header", bpy.context if context is None else context, layout)
    return layout


def draw_menu(cls: type, context: Any = None) -> RecordingLayout:
    """Run a Menu's ``draw(context)`` (including ``Menu.path_menu`` helpers) against a recorder."""
    return draw_panel(cls, context)


def draw_ui_list_item(cls: type, data: Any, item: Any, *, context: Any = None, index: int = 0,
                      active_data: Any = None, active_propname: str = "", icon: int = 0,
                      layout_type: str = "DEFAULT") -> RecordingLayout:
    """Run a UIList's ``draw_item`` for one ``item`` of ``data`` against a recorder."""
    layout = RecordingLayout(kind="ui_list_item")
    this = _DrawSelf(cls, None, {"layout_type": layout_type, "use_filter_show": False})
    this.draw_item(bpy.context if context is None else context, layout, data, item, icon,
                   data if active_data is None else active_data, active_propname, index)
    return layout
