#version 330 core
// Shared by every surface look except displacement: world-space position, normal, tangent, uv.
uniform mat4 u_model;
uniform mat4 u_view_projection;

in vec3 in_position;
in vec3 in_normal;
in vec3 in_tangent;
in vec2 in_uv;

out vec3 v_position;
out vec3 v_normal;
out vec3 v_tangent;
out vec2 v_uv;

void main() {
    vec4 world = u_model * vec4(in_position, 1.0);
    // Models use uniform scaling only, so mat3(u_model) keeps normals perpendicular.
    v_position = world.xyz;
    v_normal = normalize(mat3(u_model) * in_normal);
    v_tangent = mat3(u_model) * in_tangent;
    v_uv = in_uv;
    gl_Position = u_view_projection * world;
}
