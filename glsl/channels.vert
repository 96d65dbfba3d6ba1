#version 330 core
// The data channels' vertex stage: world position, normal, the same point at the next sampled
// frame (the cloth only; u_has_next 0 for colliders, which carry no flow), and metric depth.
uniform mat4 u_model;
uniform mat4 u_view_projection;  // as drawn: clip-space y flipped so rows read back top-down
uniform mat4 u_view;             // world -> OpenGL eye (camera looks down -z)
uniform int u_has_next;

in vec3 in_position;
in vec3 in_normal;
in vec3 in_next;

out vec3 v_normal;
out vec3 v_eye;       // eye-space position now
out vec3 v_eye_next;  // eye-space position at the next sampled frame

void main() {
    vec4 world = u_model * vec4(in_position, 1.0);
    vec4 next = u_has_next != 0 ? vec4(in_next, 1.0) : world;
    v_normal = mat3(u_model) * in_normal;
    // Eye coordinates are affine in the world position, so the rasteriser's perspective-correct
    // interpolation gives the exact eye position of the surface point under each pixel.
    v_eye = (u_view * world).xyz;
    v_eye_next = (u_view * next).xyz;
    gl_Position = u_view_projection * world;
}
