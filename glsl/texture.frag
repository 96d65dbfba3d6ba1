#version 330 core
#include "common.glsl"
uniform sampler2D u_texture_1; // sRGB texture: sampling returns linear values
in vec3 v_position;
in vec2 v_uv;
out vec4 out_color;

void main() {
    out_color = vec4(linear_to_srgb(texture(u_texture_1, v_uv).rgb), 1.0);
}
