"""A small XML tree that remembers the line of every element (for ``file:line`` errors).

A profile is untrusted: entity declarations are refused (no entity bombs, no external
entities) and nesting is bounded, so parsing costs time and memory in proportion to the file.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from xml.parsers import expat

MAX_XML_DEPTH = 256


@dataclass
class Node:
    tag: str
    attrib: dict[str, str]
    line: int
    children: list[Node] = field(default_factory=list)
    text: str = ""

    def find_all(self, tag: str) -> list[Node]:
        return [c for c in self.children if c.tag == tag]

    def find(self, tag: str) -> Node | None:
        return next((c for c in self.children if c.tag == tag), None)


class XMLSyntaxError(ValueError):
    def __init__(self, message: str, line: int) -> None:
        super().__init__(message)
        self.line = line


def parse_xml(data: str | bytes) -> Node:
    parser = expat.ParserCreate()
    parser.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
    parser.buffer_text = True
    stack: list[tuple[Node, list[str]]] = []
    root: list[Node] = []

    def refuse_entity(name: str, *_: object) -> None:
        # raised from a handler, the error ends Parse() before any entity is expanded
        raise XMLSyntaxError(f"entity declarations are not allowed (<!ENTITY {name}>)",
                             parser.CurrentLineNumber)

    def start(tag: str, attrib: dict[str, str]) -> None:
        if len(stack) >= MAX_XML_DEPTH:
            raise XMLSyntaxError(f"elements nested deeper than {MAX_XML_DEPTH} levels",
                                 parser.CurrentLineNumber)
        node = Node(tag, attrib, parser.CurrentLineNumber)
        if stack:
            stack[-1][0].children.append(node)
        else:
            root.append(node)
        stack.append((node, []))

    def end(tag: str) -> None:
        node, chunks = stack.pop()
        node.text = "".join(chunks)  # joined once: += per chunk is quadratic on long texts

    def chars(text: str) -> None:
        if stack:
            stack[-1][1].append(text)

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = chars
    parser.EntityDeclHandler = refuse_entity
    parser.UnparsedEntityDeclHandler = refuse_entity
    try:
        parser.Parse(data, True)
    except expat.ExpatError as exc:
        raise XMLSyntaxError(expat.ErrorString(exc.code), exc.lineno) from None
    return root[0]
