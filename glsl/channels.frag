#version 330 core
// Every data channel in one pass, into two float render targets:
//   0: (depth, flow x, flow y, mask id)   1: (world normal of the side seen, 0)
// Depth is metric: the distance along the optical axis (OpenCV's z). Flow is in pixels, the
// projection of the surface point's next position minus that of its current one, x right and
// y down. The mask is 1 on the cloth's front (the side its normal points to), 2 on its back,
// u_object on a collider.
uniform vec2 u_focal;      // fx, fy in pixels
uniform int u_object;      // 0: the cloth; otherwise the collider's mask id

in vec3 v_normal;
in vec3 v_eye;
in vec3 v_eye_next;

layout(location = 0) out vec4 out_depth_flow_mask;
layout(location = 1) out vec4 out_normal;

vec2 pixel(vec3 eye) {
    // OpenCV camera: x right, y down, z forward = (eye.x, -eye.y, -eye.z); principal point
    // cancels in a difference.
    return vec2(u_focal.x * eye.x / -eye.z, u_focal.y * -eye.y / -eye.z);
}

void main() {
    vec3 n = normalize(v_normal);
    float id;
    vec2 flow = vec2(0.0);
    if (u_object == 0) {
        id = gl_FrontFacing ? 1.0 : 2.0;
        flow = pixel(v_eye_next) - pixel(v_eye);
    } else {
        id = float(u_object);
    }
    out_depth_flow_mask = vec4(-v_eye.z, flow, id);
    out_normal = vec4(gl_FrontFacing ? n : -n, 0.0);
}
