#version 330 core
#include "common.glsl"
in vec3 v_position;
in vec3 v_normal;
out vec4 out_color;

void main() {
    vec3 n = facing_normal(v_normal);
    vec3 to_light = u_light_pos - v_position;
    float r2 = dot(to_light, to_light);
    vec3 c = u_k_d * u_light_intensity / r2 * max(0.0, dot(n, to_light / sqrt(r2))) * u_color.rgb;
    out_color = vec4(linear_to_srgb(c), 1.0);
}
