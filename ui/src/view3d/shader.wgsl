// The 3D view: flat-shaded triangles and unshaded lines (zero normal), premultiplied alpha out.

struct Uniforms {
    view_proj: mat4x4<f32>,
    // xyz: direction towards the light (a headlight from the eye), w unused.
    light: vec4<f32>,
};

@group(0) @binding(0) var<uniform> u: Uniforms;

struct VsIn {
    @location(0) pos: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) color: vec4<f32>,
};

struct VsOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) color: vec4<f32>,
};

@vertex
fn vs_main(v: VsIn) -> VsOut {
    var o: VsOut;
    o.clip = u.view_proj * vec4<f32>(v.pos, 1.0);
    o.normal = v.normal;
    o.color = v.color;
    return o;
}

@fragment
fn fs_main(i: VsOut) -> @location(0) vec4<f32> {
    var shade = 1.0;
    if (dot(i.normal, i.normal) > 0.0) {
        shade = 0.35 + 0.65 * abs(dot(normalize(i.normal), u.light.xyz));
    }
    return vec4<f32>(i.color.rgb * shade * i.color.a, i.color.a);
}
