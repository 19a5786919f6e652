"""Replace a generated block `<!-- BEGIN name -->` … `<!-- END name -->` in a docs page, so
that the prose stays hand-written and every number comes from a script."""

from __future__ import annotations

import os

from jaxdeploy.io import atomic_write_bytes


def replace_block(path: str, name: str, text: str) -> None:
    begin, end = f"<!-- BEGIN {name} -->", f"<!-- END {name} -->"
    page = open(path, encoding="utf-8").read() if os.path.exists(path) else ""
    block = f"{begin}\n{text.rstrip()}\n{end}"
    if begin in page and end in page:
        head, rest = page.split(begin, 1)
        _, tail = rest.split(end, 1)
        page = head + block + tail
    else:
        page = page.rstrip() + "\n\n" + block + "\n"
    atomic_write_bytes(path, page.encode("utf-8"))
