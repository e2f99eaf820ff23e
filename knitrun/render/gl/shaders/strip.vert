// Strip renderer, GL backend: one vertex per polyline point of a segment and its neighbours (GL_LINES_ADJACENCY); the geometry shader builds the
// strip. Attributes as computed on the CPU (knitrun/render/gl/gl_renderer.py, upload_segments): world position,
// unit vertex tangent (strip_raster._vertex_frames' rule), rest arc length, the yarn frame's normal N, curve index,
// and the point's index among the frame's polyline points (the axial parallax walks the polyline from there).
in vec3 in_position;
in vec3 in_tangent;
in float in_arclength;
in vec3 in_normal;
in int in_curve;
in int in_index;

out VertexData {
    vec3 position;
    vec3 tangent;
    float arclength;
    vec3 normal;
    flat int curve;
    flat int index;
} vout;

void main() {
    vout.position = in_position;
    vout.tangent = in_tangent;
    vout.arclength = in_arclength;
    vout.normal = in_normal;
    vout.curve = in_curve;
    vout.index = in_index;
}
