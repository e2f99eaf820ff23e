"""Strip renderer: the pipeline (``pipeline.render``), packs read for the renderer (``yarn_look``), the strip rasterizer, shadow maps, strip shading, texture sampling, the camera."""
