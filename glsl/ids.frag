#version 330 core
// The id pass (render/seen.py): each triangle's number, u_first + its index in the draw call, in
// the red, green and blue bytes (0, the clear, is no triangle). Drawn with a look's own vertex
// stage, so that the triangles land where the look puts them.
uniform uint u_first;
out vec4 out_id;

void main() {
    uint id = u_first + uint(gl_PrimitiveID);
    out_id = vec4(uvec4(id & 255u, (id >> 8) & 255u, (id >> 16) & 255u, 0u)) / 255.0;
}
