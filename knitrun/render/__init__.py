"""Strip renderer: the pipeline (``pipeline.render``), packs read for the renderer (``yarn_look``), the strip
rasterizer, shadow maps, strip shading, texture sampling, the camera, the ablations. This ``__init__`` imports nothing,
so ``knitrun.render.ablations`` loads without the kernels."""
