"""A reviewable edit of a session file: each gyro's ``model:`` (and, when it must change,
its ``identifiers:``) rewritten in place, everything else byte for byte.

The file is never dumped again: YAML's composer (``yaml.compose``) finds where each
``gyros[i].model`` value starts and ends in the text, and only those characters are
replaced, in the value's own style (a flow list ``[markov, temp]`` stays one; a block
list keeps its indentation, one ``- term`` a line; a comma string stays one). Comments,
key order, quoting and blank lines elsewhere are kept; the ``simulate:`` section (the
simulator's truth) is not touched.

>>> text = "gyros:\\n  - name: az   # the gyro\\n    model: [markov, temp]  # kept\\n"
>>> print(edit_models(text, {"az": ("markov", "temp", "temp2")}), end="")
gyros:
  - name: az   # the gyro
    model: [markov, temp, temp2]  # kept
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import yaml

from ..errors import ConfigError

__all__ = ["GyroLists", "gyro_lists", "edit_models"]


@dataclass(frozen=True)
class GyroLists:
    """One gyro of a session file as written: its ``model`` and ``identifiers`` (None
    when the key is absent) and the YAML nodes that hold them."""

    name: str
    model: tuple[str, ...]
    identifiers: tuple[str, ...] | None
    model_node: yaml.Node
    identifiers_node: yaml.Node | None


def _names(node: yaml.Node) -> tuple[str, ...]:
    if isinstance(node, yaml.SequenceNode):
        return tuple(str(n.value) for n in node.value)
    if isinstance(node, yaml.ScalarNode):
        return tuple(v.strip() for v in str(node.value).split(",") if v.strip())
    return ()


def gyro_lists(text: str, source: str = "session file") -> dict[str, GyroLists]:
    """Each gyro's lists as the file writes them (see :class:`GyroLists`)."""
    try:
        root = yaml.compose(text)
    except yaml.YAMLError as exc:
        raise ConfigError(f"{source}: not YAML: {exc}") from None
    if not isinstance(root, yaml.MappingNode):
        raise ConfigError(f"{source}: not a session file (no mapping at the top)")
    gyros = next((v for k, v in root.value if k.value == "gyros"), None)
    if not isinstance(gyros, yaml.SequenceNode):
        raise ConfigError(f"{source}: gyros: not a list of gyros")
    out = {}
    for i, g in enumerate(gyros.value):
        if not isinstance(g, yaml.MappingNode):
            raise ConfigError(f"{source}: gyros[{i}]: not a mapping")
        keys = {k.value: v for k, v in g.value}
        if "name" not in keys or "model" not in keys:
            raise ConfigError(f"{source}: gyros[{i}]: no name or model")
        name = str(keys["name"].value)
        ids = keys.get("identifiers")
        out[name] = GyroLists(name, _names(keys["model"]),
                              _names(ids) if ids is not None else None, keys["model"], ids)
    return out


def _render(node: yaml.Node, text: str, names: Sequence[str]) -> tuple[int, int, str]:
    """``(start, end, replacement)``: the span of ``node``'s value in ``text`` and its new
    text, in the node's own style."""
    start, end = node.start_mark.index, node.end_mark.index
    if isinstance(node, yaml.ScalarNode):
        quote = text[start] if text[start] in "'\"" else ""
        return start, end, f"{quote}{','.join(names)}{quote}"
    if isinstance(node, yaml.SequenceNode) and not node.flow_style and node.value:
        # block list: from its first "-" to the end of its last item, one item a line at
        # the first item's indentation (comments after the last item stay)
        first = node.value[0].start_mark
        line_start = text.rfind("\n", 0, first.index) + 1
        dash = text.index("-", line_start)
        indent = text[line_start:dash]
        item_gap = text[dash + 1:first.index]
        end = node.value[-1].end_mark.index
        body = ("\n" + indent).join(f"-{item_gap}{n}" for n in names)
        return dash, end, body
    return start, end, "[" + ", ".join(names) + "]"


def edit_models(text: str, models: Mapping[str, Sequence[str]],
                identifiers: Mapping[str, Sequence[str]] | None = None,
                source: str = "session file") -> str:
    """``text`` with ``gyros[name].model`` replaced by ``models[name]`` (and
    ``identifiers`` where given, for gyros that list them) and nothing else changed.
    A gyro of ``models`` the file lacks is a :class:`ConfigError`."""
    lists = gyro_lists(text, source)
    edits: list[tuple[int, int, str]] = []
    for name, names in models.items():
        if name not in lists:
            raise ConfigError(f"{source}: gyros: no gyro {name!r} (the file has "
                              f"{', '.join(lists) or 'none'})")
        g = lists[name]
        edits.append(_render(g.model_node, text, names))
        ids = (identifiers or {}).get(name)
        if ids is not None and g.identifiers_node is not None:
            edits.append(_render(g.identifiers_node, text, ids))
    for start, end, new in sorted(edits, reverse=True):
        text = text[:start] + new + text[end:]
    return text
