#version 330 core
#include "common.glsl"
in vec3 v_position;
in vec3 v_normal;
out vec4 out_color;

void main() {
    // A data view, not a colour: written as is, without sRGB encoding.
    out_color = vec4(facing_normal(v_normal) * 0.5 + 0.5, 1.0);
}
