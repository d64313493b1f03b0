"""GLSL sources (OpenGL 3.3 core) of the background (far field) and mesh passes."""

# A triangle covering the viewport, at the far plane (depth 1): drawn with depth test "<=" after the meshes.
FULLSCREEN_VS = """
#version 330
void main() {
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
    gl_Position = vec4(p * 2.0 - 1.0, 1.0, 1.0);
}
"""

# The atlas stacks the six faces vertically; each fragment finds its face and looks up the world-aligned
# far-field cube texture along forward + a * right + b * up (columns of face_to_world).
BACKGROUND_FS = """
#version 330
uniform samplerCube far_tex;
uniform mat3 face_to_world[6];
uniform float face_size;
out vec4 frag;
void main() {
    float fy = gl_FragCoord.y / face_size;
    int face = min(int(fy), 5);
    vec2 ab = vec2(gl_FragCoord.x / face_size, fy - float(face)) * 2.0 - 1.0;
    frag = texture(far_tex, face_to_world[face] * vec3(ab, 1.0));
}
"""

MESH_VS = """
#version 330
uniform mat4 view_proj;
in vec3 in_pos;
in vec3 in_col;
in vec2 in_uv;
in float in_layer;
out vec3 v_col;
out vec2 v_uv;
flat out float v_layer;
void main() {
    gl_Position = view_proj * vec4(in_pos, 1.0);
    v_col = in_col;
    v_uv = in_uv;
    v_layer = in_layer;
}
"""

# Meshes carry no polarisation. The fourth channel is 0 (polarised UV) when the far field is drawn into the
# atlas behind them, or 1 (coverage) when the far field is added per LED from its table. A texture's fourth
# channel is its cut-out mask (`meshbuffers.texture_layers`): where it samples below 0.5, nothing is drawn.
MESH_FS = """
#version 330
uniform sampler2DArray textures;
uniform float coverage;
in vec3 v_col;
in vec2 v_uv;
flat in float v_layer;
out vec4 frag;
void main() {
    vec3 c = v_col;
    if (v_layer >= 0.0) {
        vec4 t = texture(textures, vec3(v_uv, v_layer));
        if (t.a < 0.5) {
            discard;
        }
        c *= t.rgb;
    }
    frag = vec4(c, coverage);
}
"""
