"""Ray tracing over explicit fibers: the Embree scene, the path tracer, the environment light, the reference render of a
scene, fiber preview images."""
