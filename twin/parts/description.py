"""A rig description: the TOML file in which a user says what their rig is made of.

    name = "my rig"          # optional: a label
    preset = "thesis"        # optional: the rig this one starts from (``PRESETS``; default the thesis's)

    [ball]                   # one table per role (``twin.parts.ROLES``)
    part = "steel_ball"      # optional: the part in that role (default: the preset's)
    mass_kg = 0.0283         # the part's own parameters, by field name

    [actuator.amplifier]     # a field two of the part's groups share is named with its group
    rail_v = 10.0

    [physics]                # a group no part owns (``twin.parts.thesis.NOT_PART_GROUPS``), as in a
    timestep_s = 0.001       # parameter file

The result is a ``Parameters``: its ``parts`` group names the part in each role and its groups hold the values
(every command takes it as ``--rig FILE``; ``--params`` and ``--set`` apply on top). A description is refused
(``ParameterError``) naming the file, the role, the part and the field: an unknown role, part or field, a value
its field's bounds refuse, a table nested deeper than role → group → field → list, a file that is not TOML.
"""

from __future__ import annotations

import dataclasses
import tomllib
from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from typing import Any

from twin.parameters import GROUPS, PARTS_GROUP, ParameterError, Parameters, read_input_file
from twin.parts.contract import ROLES, Part, part_named

__all__ = ["PRESETS", "describe_rig", "load_rig", "preset", "rig_from_text", "rig_of"]

# The top-level keys a description may have besides its role tables and the groups no part owns.
_LABELS = ("name", "preset")
# role → group → field → list: one level deeper than a parameter file.
_MAX_DEPTH = 4


def _preset_dir() -> Any:
    return resources.files("twin.parts").joinpath("presets")


def _preset_names() -> list[str]:
    return sorted(p.name.removesuffix(".toml") for p in _preset_dir().iterdir() if p.name.endswith(".toml"))


PRESETS: tuple[str, ...] = ("thesis", *(n for n in _preset_names() if n != "thesis"))


def preset(name: str) -> Parameters:
    """The preset ``name``'s rig (``thesis``: the defaults)."""
    if name not in PRESETS:
        raise ParameterError(f"preset = {name!r}: no such preset (there are: {', '.join(PRESETS)})")
    if name == "thesis":
        return Parameters()
    text = _preset_dir().joinpath(f"{name}.toml").read_text(encoding="utf-8")
    return rig_from_text(text, origin=f"preset {name!r}", allow_preset=False)


def load_rig(path: str | Path) -> Parameters:
    """The rig a description file describes (see the module's doc); ``ParameterError`` naming the file and the
    field for anything else."""
    path = Path(path)
    raw = read_input_file(path, "rig description", "a rig description is a few dozen lines of TOML")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ParameterError(f"{path}: not a UTF-8 text file ({exc.reason} at byte {exc.start})") from None
    return rig_from_text(text, origin=str(path))


def rig_of(value: str) -> Parameters:
    """The rig ``--rig-file`` (or the environment's ``rig``) names: a description file (``….toml``) or a preset
    by name."""
    if value.lower().endswith(".toml"):
        return load_rig(value)
    if value not in PRESETS:
        raise ParameterError(
            f"--rig-file {value[:80]!r}: neither a rig description (a file ending in .toml) nor a preset "
            f"({', '.join(PRESETS)})"
        )
    return preset(value)


def rig_from_text(text: str, *, origin: str, allow_preset: bool = True) -> Parameters:
    """The rig a description's text describes; refusals name ``origin`` (the file)."""
    try:
        data = tomllib.loads(text)
    except (tomllib.TOMLDecodeError, RecursionError) as exc:
        raise ParameterError(f"{origin}: not a valid TOML file: {str(exc)[:200]}") from None
    deep = _too_deep(data)
    if deep is not None:
        raise ParameterError(
            f"{origin}: nested deeper than a rig description (role → group → field) at {deep}"
        )
    for key in _LABELS:
        if key in data and not isinstance(data[key], str):
            raise ParameterError(f"{origin}: {key} = {data[key]!r} is not a string")
    if "preset" in data and not allow_preset:
        raise ParameterError(
            f"{origin}: a preset starts from the thesis's rig; it names no preset of its own"
        )
    base = preset(data["preset"]) if "preset" in data else Parameters()
    names: dict[str, Any] = {}
    values: list[tuple[str, dict[str, Any]]] = []  # (where, values): a refusal names the role and its part
    for key, table in data.items():
        if key in _LABELS:
            continue
        if not isinstance(table, Mapping):
            raise ParameterError(
                f"{origin}: {key} = {table!r} is not a table: a description has a table per role "
                f"({', '.join(ROLES)}) or per group no part owns"
            )
        if key in ROLES:
            role_names, where, role_values = _role_table(key, table, base, origin)
            names.update(role_names)
            values.append((where, role_values))
        elif key in GROUPS and not _owned(key):
            values.append((origin, {f"{key}.{field}": value for field, value in table.items()}))
        elif key in GROUPS:
            raise ParameterError(
                f"{origin}: [{key}] belongs to a part: set it in its role's table ([{_owner_role(key)}])"
            )
        else:
            raise ParameterError(
                f"{origin}: [{key}] is neither a role ({', '.join(ROLES)}) nor a group no part owns "
                f"({', '.join(g for g in GROUPS if not _owned(g))})"
            )
    rig = base.with_overrides(names, origin=origin) if names else base
    for where, items in values:
        rig = rig.with_overrides(items, origin=where) if items else rig
    return rig


def _role_table(
    role: str, table: Mapping[str, Any], base: Parameters, origin: str
) -> tuple[dict[str, Any], str, dict[str, Any]]:
    """The part a role's table names, where its values come from (for a refusal) and its values by dotted
    name."""
    name = table.get("part", getattr(base.parts, role))
    if not isinstance(name, str):
        raise ParameterError(f"{origin}: [{role}] part = {str(name)[:80]!r} is not a part's name")
    try:
        part = part_named(role, name)  # type: ignore[arg-type]  # role is one of ROLES
    except ParameterError as exc:
        raise ParameterError(f"{origin}: [{role}] {exc}") from None
    where = f"{origin}: [{role}] part {part.name!r}"
    fields = {group: {f.name for f in dataclasses.fields(cls)} for group, cls in part.groups.items()}
    values: dict[str, Any] = {}
    for key, value in table.items():
        if key == "part":
            continue
        if key in fields and isinstance(value, Mapping):
            for field, item in value.items():
                if field not in fields[key]:
                    raise ParameterError(
                        f"{where}: no field {key}.{field} (its fields: {sorted(fields[key])})"
                    )
                values[f"{key}.{field}"] = item
            continue
        groups = [group for group, names in fields.items() if key in names]
        if not groups:
            known = sorted(f for names in fields.values() for f in names)
            raise ParameterError(f"{where}: no field {key!r} (its fields: {', '.join(known) or 'none'})")
        if len(groups) > 1:
            raise ParameterError(
                f"{where}: {key!r} is a field of {' and '.join(groups)}: write it as "
                f"[{role}.{groups[0]}] {key} = …"
            )
        values[f"{groups[0]}.{key}"] = value
    return {f"{PARTS_GROUP}.{role}": part.name}, where, values


def _owned(group: str) -> bool:
    return _owner_role(group) is not None


def _owner_role(group: str) -> str | None:
    """The role whose thesis part owns the table's group ``group`` (None: no part owns it)."""
    for role in ROLES:
        part = part_named(role, getattr(Parameters().parts, role))
        if group in part.groups:
            return role
    return None


def _too_deep(data: Any) -> str | None:
    """Where ``data`` nests deeper than ``_MAX_DEPTH`` (iterative: a hostile file cannot recurse)."""
    stack: list[tuple[Any, str, int]] = [(data, "", 0)]
    while stack:
        obj, where, depth = stack.pop()
        if isinstance(obj, Mapping):
            items: Any = ((f"{where}.{k}" if where else str(k), v) for k, v in obj.items())
        elif isinstance(obj, list):
            items = ((f"{where}[{i}]", v) for i, v in enumerate(obj))
        else:
            continue
        if depth >= _MAX_DEPTH:
            return where[:80]
        stack.extend((v, w, depth + 1) for w, v in items)
    return None


def describe_rig(params: Parameters) -> list[dict[str, str]]:
    """The rig's parameters, part by part: role, part, name, value, unit, bounds and source (``params --rig``)."""
    rows = []
    for role in ROLES:
        part: Part = part_named(role, getattr(params.parts, role))
        for group in part.groups:
            values = params.group(group)
            for f in dataclasses.fields(values):
                md = f.metadata
                bounds = " ".join(
                    f"{word} {md[key]!r}"
                    for key, word in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<="))
                    if md.get(key) is not None
                )
                rows.append(
                    {
                        "role": role,
                        "part": part.name,
                        "name": f"{group}.{f.name}",
                        "value": repr(getattr(values, f.name)),
                        "unit": str(md.get("unit", "")),
                        "bounds": bounds,
                        "source": str(md.get("source", "")),
                    }
                )
    return rows
