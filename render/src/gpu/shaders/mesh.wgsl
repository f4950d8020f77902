// Lit meshes: ambient (vertex ambient colour times the ambient weight) + Lambert (vertex colour)
// + Blinn-Phong (white), two-sided.

struct Globals {
    view_proj: mat4x4<f32>,
    eye: vec4<f32>,
    light_towards: vec4<f32>,
};

struct Object {
    world_from_object: mat4x4<f32>,
    normal_matrix: mat4x4<f32>,
    // ambient, diffuse, specular, shininess
    material: vec4<f32>,
    // x: opacity
    opacity: vec4<f32>,
};

@group(0) @binding(0) var<uniform> globals: Globals;
@group(1) @binding(0) var<uniform> object: Object;

struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) colour: vec4<f32>,
    @location(3) ambient: vec3<f32>,
};

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) colour: vec4<f32>,
    @location(3) ambient: vec3<f32>,
};

@vertex
fn vs_main(v: VertexIn) -> VertexOut {
    var out: VertexOut;
    let world = object.world_from_object * vec4<f32>(v.position, 1.0);
    out.clip = globals.view_proj * world;
    out.world = world.xyz;
    out.normal = (object.normal_matrix * vec4<f32>(v.normal, 0.0)).xyz;
    out.colour = v.colour;
    out.ambient = v.ambient;
    return out;
}

@fragment
fn fs_main(in: VertexOut, @builtin(front_facing) front: bool) -> @location(0) vec4<f32> {
    var n = normalize(in.normal);
    if (!front) {
        n = -n;
    }
    let l = normalize(globals.light_towards.xyz);
    let v = normalize(globals.eye.xyz - in.world);
    let h = normalize(l + v);
    let m = object.material;
    let lambert = max(dot(n, l), 0.0);
    let spec = select(0.0, pow(max(dot(n, h), 0.0), m.w), lambert > 0.0);
    let rgb = in.ambient * m.x + in.colour.rgb * (m.y * lambert) + vec3<f32>(m.z * spec);
    return vec4<f32>(rgb, in.colour.a * object.opacity.x);
}
