"""XML documents read safely (no DTD, no entities; UTF-16/32 normalised), and tag helpers."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from typing import TYPE_CHECKING, Final

if TYPE_CHECKING:
    from mapmatch.trace.readers.raw import Context

__all__ = ["child_name", "local_tag", "xml_root"]

_DOCTYPE: Final = re.compile(rb"<!\s*(DOCTYPE|ENTITY)", re.IGNORECASE)


def local_tag(tag: str) -> str:
    """A tag without its namespace, lower case."""
    return tag.rsplit("}", 1)[-1].lower()


def _check_no_dtd(data: bytes, ctx: Context) -> bytes:
    """Reject DTDs (no entity expansion, no external entities); normalise UTF-16/32 to UTF-8."""
    head = data[:4]
    if head.startswith((b"\xff\xfe", b"\xfe\xff")) or b"\x00" in head:
        for codec in ("utf-32", "utf-16"):
            try:
                text = data.decode(codec)
            except UnicodeDecodeError:
                continue
            data = re.sub(r"^\s*<\?xml[^>]*\?>", "", text).encode("utf-8")
            break
        else:
            msg = "has an unknown text encoding; save it as UTF-8"
            raise ctx.error(msg)
    if _DOCTYPE.search(data):
        msg = (
            "contains a DOCTYPE/ENTITY declaration, which is refused for safety; "
            "remove the <!DOCTYPE ...> line"
        )
        raise ctx.error(msg)
    return data


def xml_root(data: bytes, ctx: Context, expected: str) -> ET.Element:
    """The root element of a safe, well-formed document, checked to be ``<expected>``."""
    data = _check_no_dtd(data, ctx)
    try:
        root = ET.fromstring(data)
    except ET.ParseError as exc:
        msg = f"is not well-formed XML: {exc}"
        raise ctx.error(msg) from exc
    if local_tag(root.tag) != expected:
        msg = f"root element is <{local_tag(root.tag)}>, expected <{expected}>"
        raise ctx.error(msg)
    return root


def child_name(el: ET.Element) -> str | None:
    """The text of the element's ``<name>`` child, if any."""
    for child in el:
        if local_tag(child.tag) == "name" and child.text and child.text.strip():
            return child.text.strip()
    return None
