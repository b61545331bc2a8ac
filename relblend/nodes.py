"""Reading Blender's shader node trees: which node feeds which socket.

Shared by the export (materials, the world's sky) and the sky bake (is the world's sky
procedural?), so both read a tree the same way: links through reroutes, a muted or
invalid link is no link.
"""

from __future__ import annotations

#: Reroutes followed before a chain counts as broken (a cycle of reroutes ends there).
MAX_REROUTES = 64


def node_tree(id_data):
    """The node tree of a material or world, or None when it does not use nodes.

    (``use_nodes`` is deprecated from Blender 5.0 on, where node trees are always used.)
    """
    import bpy

    if bpy.app.version < (5, 0, 0) and not getattr(id_data, "use_nodes", False):
        return None
    return id_data.node_tree


def linked_node(socket):
    """The node feeding an input socket (through reroutes), or None."""
    seen = 0
    while socket.is_linked and seen < MAX_REROUTES:
        link = socket.links[0]
        if not link.is_valid or link.is_muted:
            return None
        node = link.from_node
        if node.type == "REROUTE":
            socket = node.inputs[0]
            seen += 1
            continue
        return node
    return None


def world_surface(world):
    """The node feeding the world output's Surface (normally a Background), or None."""
    tree = node_tree(world) if world is not None else None
    out = (tree.get_output_node("CYCLES") or tree.get_output_node("ALL")) if tree else None
    return linked_node(out.inputs["Surface"]) if out is not None else None


def background_source(world):
    """The node feeding the world's Background colour, or None (a constant colour, or no
    Background)."""
    bg = world_surface(world)
    if bg is None or bg.type != "BACKGROUND":
        return None
    return linked_node(bg.inputs["Color"])
