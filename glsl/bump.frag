#version 330 core
#include "common.glsl"
in vec3 v_position;
in vec3 v_normal;
in vec3 v_tangent;
in vec2 v_uv;
out vec4 out_color;

void main() {
    vec3 n = bump_normal(facing_normal(v_normal), v_tangent, v_uv);
    out_color = vec4(linear_to_srgb(blinn_phong(v_position, n, u_color.rgb)), 1.0);
}
