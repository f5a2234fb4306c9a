"""Pictures of the map: a grid layer as an image (:mod:`atlas.render.layers`) or a transparent overlay
(:mod:`atlas.render.overlay`), and the whole layout as a scene
(:mod:`atlas.render.scene`) drawn as PNG (:mod:`atlas.render.png`) or SVG (:mod:`atlas.render.svg`)."""

from atlas.render.layers import RenderError, encode_npy, encode_png, label_image, layer_image, render_layer
from atlas.render.overlay import overlay_image
from atlas.render.png import render_png
from atlas.render.scene import LayoutScene, NothingToDrawError, layout_scene
from atlas.render.svg import render_svg

__all__ = [
    "LayoutScene",
    "NothingToDrawError",
    "RenderError",
    "encode_npy",
    "encode_png",
    "label_image",
    "layer_image",
    "layout_scene",
    "overlay_image",
    "render_layer",
    "render_png",
    "render_svg",
]
