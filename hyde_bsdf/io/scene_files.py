"""The files a Mitsuba 3 scene reads: the scene, its ``<include>``s, spectra, textures and meshes.

:func:`scene_files` follows the graph as Mitsuba 3.9's parser resolves it (``src/core/parser.cpp``,
``FileResolver::resolve``: the first folder of the resolver in which the relative path exists, else
the path as written, relative to the working folder):

* loading ``scene.xml`` puts its folder first in the resolver (then the working folder);
* ``<include filename=F>`` resolves F with the *including* file's folder first, and parses the
  included file with that resolver, so an ``<include>`` or a ``<spectrum filename>`` in it is
  found beside the including file first;
* ``<path value=V/>`` (a child of the root) puts V (beside the XML file, else resolved) first;
* a plugin's file -- ``<string name="filename">`` of a bitmap, mesh, envmap, measured table -- is
  resolved when the plugin is built, after parsing, with the main file's resolver: in an included
  file too it is found beside the *main* scene, not beside the included file;
* ``$name`` is filled from the caller's parameters, then the files' ``<default>``s.

The command line's output gate refuses an output that is one of these files
(:func:`hyde_bsdf.app.args.run_inputs`).
"""
from __future__ import annotations

import os
import re
import xml.etree.ElementTree as ET
from pathlib import Path

from hyde_bsdf.io.arrays import check_image_memory
from hyde_bsdf.io.input_gate import check_input

__all__ = ["scene_files", "MAX_INCLUDE_DEPTH"]

#: deepest ``<include>`` nesting followed (Mitsuba stops at 15 too)
MAX_INCLUDE_DEPTH = 15
_PARAM = re.compile(r"\$([A-Za-z_][A-Za-z0-9_]*)")


def _resolve(name: str, folders) -> Path:
    p = Path(name).expanduser()
    if p.is_absolute():
        return p
    return next((f / p for f in folders if (f / p).exists()), Path.cwd() / p)


def _root(path: Path):
    """The parsed root of an XML file (pugixml accepts "--" in comments, ElementTree does not), or None."""
    try:
        text = Path(check_input(path, "scene file", stdin=False)).read_text(encoding="utf-8", errors="replace")
        return ET.fromstring(re.sub(r"<!--.*?-->", "", text, flags=re.S))
    except (ET.ParseError, OSError):
        return None                            # Mitsuba's parser reports what is wrong with it


def scene_files(path, params: dict | None = None) -> list[Path]:
    """The scene ``path`` and every file its graph names (module docstring), each once, in the
    order met; files that do not exist are listed where Mitsuba would look last.  A file of the
    graph that is a FIFO or a device is refused here (the input gate), before anything opens it."""
    path = Path(path)
    values = {str(k): str(v) for k, v in (params or {}).items()}
    main: list[Path] = [path.parent.resolve()]            # the main resolver; <path>s go first
    files, plugin_files = [path], []

    def walk(xml: Path, resolver: list, depth: int) -> None:
        root = _root(xml)
        if root is None:
            return
        for d in root.iter("default"):
            values.setdefault(d.get("name"), d.get("value"))

        def fill(text):
            return _PARAM.sub(lambda m: values.get(m.group(1), m.group(0)), text or "")

        for top in root:                       # document order: a <path> counts from where it stands
            if top.tag == "path" and top.get("value"):
                here = xml.parent / fill(top.get("value"))
                resolver.insert(0, here if here.exists() else _resolve(fill(top.get("value")), resolver))
                continue
            for el in top.iter():
                name = fill(el.get("filename") or el.get("value"))
                if el.tag == "include" and el.get("filename") and depth < MAX_INCLUDE_DEPTH:
                    inner = [xml.parent.resolve(), *resolver]
                    found = _resolve(name, inner)
                    if found not in files:
                        files.append(found)
                        walk(found, inner, depth + 1)
                elif el.tag == "spectrum" and el.get("filename"):
                    files.append(_resolve(name, resolver))
                elif el.tag == "string" and (el.get("name") or "").endswith("filename") and el.get("value"):
                    plugin_files.append(name)

    walk(path, main, 0)
    files += [_resolve(name, main) for name in plugin_files]
    for p in files[1:]:
        if os.path.lexists(p):
            check_input(p, f"scene {str(path)!r}: file", stdin=False)
            check_image_memory(p, f"scene {str(path)!r}: image")      # its size from its header
    return list(dict.fromkeys(files))
