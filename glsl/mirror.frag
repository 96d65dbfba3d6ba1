#version 330 core
#include "common.glsl"
uniform samplerCube u_texture_cubemap;
in vec3 v_position;
in vec3 v_normal;
out vec4 out_color;

void main() {
    vec3 n = facing_normal(v_normal);
    vec3 w_o = u_cam_pos - v_position;
    vec3 w_i = reflect(-w_o, n);
    out_color = vec4(linear_to_srgb(texture(u_texture_cubemap, w_i).rgb), 1.0);
}
