#version 330 core
uniform mat4 u_model;
uniform mat4 u_view_projection;
in vec3 in_position;

void main() {
    gl_Position = u_view_projection * (u_model * vec4(in_position, 1.0));
}
