#version 330 core
#include "common.glsl"
out vec4 out_color;

void main() {
    out_color = vec4(linear_to_srgb(u_color.rgb), 1.0);
}
