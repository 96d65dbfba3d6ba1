#version 330 core
#include "common.glsl"
in vec3 v_position;
in vec3 v_normal;
out vec4 out_color;

void main() {
    vec3 c = blinn_phong(v_position, facing_normal(v_normal), u_color.rgb);
    out_color = vec4(linear_to_srgb(c), 1.0);
}
