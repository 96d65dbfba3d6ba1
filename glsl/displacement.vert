#version 330 core
// p' = p + n * h(uv) * k_h, applied in world space so that a sphere's displacement does not
// shrink with its radius.
uniform mat4 u_model;
uniform mat4 u_view_projection;
uniform sampler2D u_texture_2;
uniform float u_height_scaling;

in vec3 in_position;
in vec3 in_normal;
in vec3 in_tangent;
in vec2 in_uv;

out vec3 v_position;
out vec3 v_normal;
out vec3 v_tangent;
out vec2 v_uv;

void main() {
    vec3 n = normalize(mat3(u_model) * in_normal);
    vec4 world = u_model * vec4(in_position, 1.0);
    float h = texture(u_texture_2, in_uv).r;
    world.xyz += n * h * u_height_scaling;
    v_position = world.xyz;
    v_normal = n;
    v_tangent = mat3(u_model) * in_tangent;
    v_uv = in_uv;
    gl_Position = u_view_projection * world;
}
