"""The XML side of Mitsuba scene files: the tree with line numbers, ``$name`` parameters,
property values, references by id and the errors (``MitsubaError``) that name file, line and
element. ``Reader`` is the state of one load, passed to every loader of a kind."""

from __future__ import annotations

import os
import re
import xml.parsers.expat
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple

import torch

from ..scene import Material


class MitsubaError(ValueError):
    """A scene file outside the supported subset, or malformed."""


@dataclass
class Node:
    tag: str
    attrs: Dict[str, str]
    line: int
    children: List["Node"] = field(default_factory=list)

    def describe(self) -> str:
        shown = [f'{k}="{self.attrs[k]}"' for k in ("type", "name", "id") if k in self.attrs]
        return "<" + " ".join([self.tag] + shown) + ">"


_FLOAT32_MAX = 3.4028234663852886e38

# Deeper nesting than any scene needs is refused (the loader recurses over the tree).
_MAX_DEPTH = 64


def parse_xml(path: str) -> Node:
    stack: List[Node] = []
    root: List[Node] = []
    parser = xml.parsers.expat.ParserCreate()

    def start(tag, attrs):
        if len(stack) >= _MAX_DEPTH:
            raise MitsubaError(f"{path}:{parser.CurrentLineNumber}: <{tag}>: elements nested "
                               f"deeper than {_MAX_DEPTH} levels")
        node = Node(tag, dict(attrs), parser.CurrentLineNumber)
        (stack[-1].children if stack else root).append(node)
        stack.append(node)

    def end(tag):
        stack.pop()

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    with open(path, "rb") as f:
        data = f.read()
    try:
        parser.Parse(data, True)
    except xml.parsers.expat.ExpatError as error:
        raise MitsubaError(f"{path}:{error.lineno}: malformed XML: "
                           f"{xml.parsers.expat.ErrorString(error.code)}") from None
    except LookupError as error:  # the XML declaration names an encoding Python lacks
        raise MitsubaError(f"{path}:{parser.CurrentLineNumber}: {error}") from None
    return root[0]


_PARAM = re.compile(r"\$([A-Za-z_][A-Za-z0-9_]*)")
PROPERTY_TAGS = ("float", "integer", "boolean", "string", "rgb", "spectrum", "point",
                 "vector", "transform", "ref")
PLUGIN_TAGS = ("bsdf", "texture", "emitter", "film", "rfilter", "sampler", "shape",
               "sensor", "integrator")


class Reader:
    """The state of one load: the file, its parameters and ids, the BSDFs and textures made
    so far (each element becomes one object, however often it is referred to), and the
    ``MitsubaScene`` being filled in. Its methods read XML values; the loaders of each kind
    (sensors, shapes, ...) take it as their first argument."""

    def __init__(self, path: str, result):
        self.path = path
        self.directory = os.path.dirname(os.path.abspath(path))
        self.params: Dict[str, str] = {}
        self.used_params: set = set()
        self.ids: Dict[str, Node] = {}
        self.bsdf_cache: Dict[int, Material] = {}
        self.texture_cache: Dict[int, torch.Tensor] = {}
        self.result = result  # the MitsubaScene
        self.last_ref: Optional[Node] = None  # names the culprit of a cycle of references

    # errors and values

    def fail(self, node: Node, message: str):
        raise MitsubaError(f"{self.path}:{node.line}: {node.describe()}: {message}")

    def attr(self, node: Node, name: str, required: bool = True) -> Optional[str]:
        if name not in node.attrs:
            if required:
                self.fail(node, f"missing attribute '{name}'")
            return None
        return node.attrs[name]

    def substitute(self, node: Node) -> None:
        for key, value in node.attrs.items():
            def repl(m, node=node):
                name = m.group(1)
                if name not in self.params:
                    self.fail(node, f"undefined parameter ${name} (give it to load_mitsuba as "
                                    f"{name}=... or declare a <default name=\"{name}\">)")
                self.used_params.add(name)
                return self.params[name]
            node.attrs[key] = _PARAM.sub(repl, value)
        for child in node.children:
            self.substitute(child)

    def numbers(self, node: Node, text: str, counts: Sequence[int]) -> List[float]:
        parts = [p for p in re.split(r"[,\s]+", text.strip()) if p]
        try:
            values = [float(p) for p in parts]
        except ValueError:
            self.fail(node, f"expected numbers, got {text!r}")
        if not all(abs(x) <= _FLOAT32_MAX for x in values):  # NaN fails too
            self.fail(node, f"expected finite numbers (as float32), got {text!r}")
        if len(values) not in counts:
            self.fail(node, f"expected {' or '.join(map(str, counts))} numbers, got {len(values)}")
        return values

    def float_value(self, node: Node) -> float:
        if node.tag not in ("float", "integer"):
            self.fail(node, "expected a <float>")
        return self.numbers(node, self.attr(node, "value"), (1,))[0]

    def int_value(self, node: Node) -> int:
        if node.tag != "integer":
            self.fail(node, "expected an <integer>")
        text = self.attr(node, "value")
        try:
            return int(text)
        except ValueError:
            self.fail(node, f"expected an integer, got {text!r}")

    def bool_value(self, node: Node) -> bool:
        if node.tag != "boolean":
            self.fail(node, "expected a <boolean>")
        text = self.attr(node, "value").strip().lower()
        if text not in ("true", "false"):
            self.fail(node, f"expected true or false, got {text!r}")
        return text == "true"

    def string_value(self, node: Node) -> str:
        if node.tag != "string":
            self.fail(node, "expected a <string>")
        return self.attr(node, "value")

    def vector_value(self, node: Node) -> List[float]:
        if node.tag not in ("point", "vector"):
            self.fail(node, "expected a <point> or <vector>")
        if "value" in node.attrs:
            return self.numbers(node, node.attrs["value"], (3,))
        return [self.numbers(node, node.attrs.get(k, "0"), (1,))[0] for k in "xyz"]

    def file(self, node: Node, name: str) -> str:
        name = name.replace("\\", "/")
        full = name if os.path.isabs(name) else os.path.join(self.directory, name)
        if not os.path.isfile(full):
            self.fail(node, f"file not found: {full}")
        return full

    # plugins and their properties

    def properties(self, plugin: Node) -> Tuple[Dict[str, Node], List[Node]]:
        """Named properties of a plugin element, and its nested plugins (refs included)."""
        props: Dict[str, Node] = {}
        nested: List[Node] = []
        for child in plugin.children:
            if child.tag in PLUGIN_TAGS or (child.tag == "ref" and "name" not in child.attrs):
                nested.append(child)
                if child.tag in ("texture", "bsdf") and "name" in child.attrs:
                    props[child.attrs["name"]] = child
                continue
            if child.tag not in PROPERTY_TAGS:
                self.fail(child, f"unsupported element inside <{plugin.tag}>")
            name = self.attr(child, "name")
            if name in props:
                self.fail(child, f"property '{name}' given twice")
            props[name] = child
        return props, nested

    def leftovers(self, plugin: Node, props: Dict[str, Node], kind: str) -> None:
        for name, node in props.items():
            self.fail(node, f"property '{name}' of {kind} '{plugin.attrs.get('type')}' is not "
                            "supported")

    def deref(self, node: Node, tags: Tuple[str, ...]) -> Node:
        if node.tag != "ref":
            return node
        self.last_ref = node
        ref = self.attr(node, "id")
        if ref not in self.ids:
            self.fail(node, f"unknown id '{ref}'")
        target = self.ids[ref]
        if target.tag not in tags:
            self.fail(node, f"id '{ref}' is a <{target.tag}>, expected <{'> or <'.join(tags)}>")
        return target
