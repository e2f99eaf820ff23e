"""The strip renderer's OpenGL backend (``gl_renderer``): the CPU renderer's model in GLSL, drawn headless (EGL)."""
