#version 330 core
#include "common.glsl"
// Textured displacement blended with a cubemap reflection:
// colour = (1 - reflectivity) * BlinnPhong(albedo = texture) + reflectivity * cubemap(w_i).
uniform sampler2D u_texture_1;
uniform samplerCube u_texture_cubemap;
uniform float u_reflectivity;
in vec3 v_position;
in vec3 v_normal;
in vec3 v_tangent;
in vec2 v_uv;
out vec4 out_color;

void main() {
    vec3 n = bump_normal(facing_normal(v_normal), v_tangent, v_uv);
    vec3 albedo = texture(u_texture_1, v_uv).rgb * u_color.rgb;
    vec3 lit = blinn_phong(v_position, n, albedo);
    vec3 w_i = reflect(v_position - u_cam_pos, n);
    vec3 reflected = texture(u_texture_cubemap, w_i).rgb;
    out_color = vec4(linear_to_srgb(mix(lit, reflected, u_reflectivity)), 1.0);
}
