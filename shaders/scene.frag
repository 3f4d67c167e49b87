#version 410 core
// Scene shading: lights, then the material slots in order (reflect, refract, emissive)
// (reflect, refract, emissive). Each slot switches on the instance's variant index.
#include "camera.glsl"
#include "view_axis.glsl"
#include "visibility.glsl"
#include "lights.glsl"
#include "shadows.glsl"
#include "ggx.glsl"
#include "ambient.glsl"
#include "subsurface.glsl"
#include "rect_lights.glsl"
#ifdef CLOUD_SHADOWS
#include "clouds.glsl"
#endif
#ifdef CAUSTICS
#include "water_waves.glsl"
#include "ripples.glsl"
#include "caustics.glsl"
// The waters (the Caustics block's slots) this draw's batch reaches into, -1 after the last
// (engine/render/caustics.py CausticBlock.slots_of).
uniform ivec4 caustic_waters;
#ifdef CAUSTIC_LAMPS
// The share of each lamp of the block's caustic_lamps that the waters gather at the pixel
// (caustic_lamp_light), set before the lamps' loops; lamp_light reads its lamp's.
vec4 lamp_caustic = vec4(1.0);
#endif
#endif
#ifdef FOAM
#include "foam.glsl"
#endif
#include "hdr.glsl"
#include "way.glsl"
uniform samplerCube sky_map;
#define FOG_SKY sky_map   // (Fog.aerial_perspective reads the sky's cube map through it: fog.glsl)
#include "fog.glsl"

uniform sampler2D albedo_map;
uniform bool has_albedo_map;
uniform float sky_face_size;   // texels across one face of sky_map
uniform int transparent;        // the transparent slot (instances.blend_code): 0 opaque; its colour
                                // premultiplied by its alpha: 1 all of it, 2 its diffuse light only,
                                // 3 all of it, a decal's cut (nothing drawn where it has no alpha)
uniform vec3 dielectric_f0;     // what a non-metal reflects head on: 0.16 x its batch's Material.reflectance^2
                                // x its specular_color, each channel held at 1
#ifdef ALPHA_CUTOFF
uniform float alpha_cutoff;     // a cutout's (its batch's Material.alpha_cutoff)
#endif

in vec3 v_world_pos;
in vec3 v_normal;
in vec2 v_uv;
#ifdef SECOND_UV_MAPS
in vec2 v_uv2;  // the mesh's second UV set (Mesh.second_uvs): MAP_UV picks it for the maps that read it
#endif
#include "uv_sets.glsl"
#include "lightmap.glsl"
flat in vec4 v_color;
flat in vec4 v_surface;
flat in vec4 v_reflect;
flat in vec4 v_tint;
flat in uvec4 v_slots;
#ifdef VERTEX_COLOR
in vec4 v_vertex_color;  // the mesh's colour here (Mesh.colors, RGBA), multiplied into the material's
#endif
#ifdef SCREEN_OCCLUSION
// The camera's screen-space ambient occlusion (engine/render/screen_occlusion.py; the opaque
// draws of the root view and of the reflection levels it reaches, each level's views drawn one
// by one), at half the level's size or all of it: r the light from all round's share, g the
// direct light's, b the texel's distance along its view's axis (-1: sky), a the sun's past
// the camera's contact shadows (1 without them).
uniform sampler2D screen_occlusion;
#ifdef CONTACT_LAMPS
// The lamps' shares past their contact shadows (PointLight.contact_shadows; the image beside the
// occlusion's, its size): rgba a channel each, which a lamp's Lights row names.  Brought to the
// pixel with the same weights as the shares (screen_occlusion_shares sets it).
uniform sampler2D screen_contact_lamps;
vec4 lamp_contact = vec4(1.0);
#endif

// The shares at this pixel: the four texels about it, by their bilinear weights each times
// how near its distance lies to this pixel's (a joint bilateral upsample: across a silhouette
// the other side's texels drop out; at full size the pixel's own texel alone).
vec3 screen_occlusion_shares() {
    float here = 1.0 / gl_FragCoord.w;  // the distance along the view's axis (1 / clip w)
    vec2 size = vec2(textureSize(screen_occlusion, 0));
    vec2 scale = size / camera.viewport.zw;
    vec2 at = gl_FragCoord.xy * scale - 0.5;
    vec2 cell = floor(at);
    vec2 f = at - cell;
    // Off by 2% of the distance, or by what a texel's step across this surface spans: another surface.
    float tolerance = 0.02 * here + 2.0 * fwidth(here) / min(scale.x, scale.y);
    ivec2 last = ivec2(size) - 1;
    vec3 total = vec3(0.0);
    float weights = 0.0;
    vec3 nearest = vec3(1.0);
    float nearest_gap = 1e30;
#ifdef CONTACT_LAMPS
    vec4 lamps = vec4(0.0), nearest_lamps = vec4(1.0);
#endif
    for (int i = 0; i < 4; ++i) {
        ivec2 offset = ivec2(i & 1, i >> 1);
        ivec2 at = clamp(ivec2(cell) + offset, ivec2(0), last);
        vec4 texel = texelFetch(screen_occlusion, at, 0);
        if (texel.b < 0.0) continue;  // the sky's
        vec2 bilinear = mix(1.0 - f, f, vec2(offset));
        float gap = abs(texel.b - here);
        float weight = bilinear.x * bilinear.y * max(0.0, 1.0 - gap / tolerance);
        total += weight * texel.rga;
        weights += weight;
#ifdef CONTACT_LAMPS
        vec4 lamps_here = texelFetch(screen_contact_lamps, at, 0);
        lamps += weight * lamps_here;
        nearest_lamps = gap < nearest_gap ? lamps_here : nearest_lamps;
#endif
        if (gap < nearest_gap) {
            nearest_gap = gap;
            nearest = texel.rga;
        }
    }
#ifdef CONTACT_LAMPS
    lamp_contact = weights > 1e-4 ? lamps / weights : nearest_lamps;
#endif
    return weights > 1e-4 ? total / weights : nearest;
}
#endif

// Reflection levels draw only the pixels of their own view (the node image mirror_claim.frag
// wrote): the MASKED build (engine/render/scene_pass.py), so a root view's program has no
// fetch (llvmpipe would run it for every pixel behind a uniform test).
#ifdef MASKED
uniform usampler2D node_map;
#ifndef NODE_STEP
#define NODE_STEP 1
#endif
#endif
// A pixel the draw leaves out: another view's (MASKED, read from the node image) or a
// cutout's hole (ALPHA_CUTOFF).  Known early, discarded last
// (DISCARD_DROPPED before every write of the outputs): a discard ends its pixel's invocation,
// and the derivatives of the others in its 2x2 quad (the checker's filter, the filtered
// roughness, every implicit texture level) are undefined after it (GLSL 4.10, section 8.9:
// implicit derivatives in non-uniform control flow).  An H200 shaded the pixels beside
// another view's otherwise than the unmasked build while the node test discarded first.
bool dropped_pixel = false;
#define DISCARD_DROPPED() if (dropped_pixel) discard
#ifdef BATCHED_VIEWS
// Several views in one draw (a reflection level's, a cube map's faces): scene.vert's
// INSTANCED_VIEWS build or scene_layered.geom says which view (node index and eye) each
// triangle was drawn for.
flat in uint v_node;
flat in vec4 v_eye;      // w: its way_scale (view_axis.glsl)
flat in vec3 v_eye_axis;  // its axis where it is orthographic (0: perspective; view_axis.glsl)
#define node_index v_node
#define VIEW_POINT v_eye.xyz
#define VIEW_WAY_SCALE v_eye.w
#define VIEW_AXIS v_eye_axis
#ifdef FOG
flat in vec4 v_clip;
#define VIEW_ENTRY v_clip
#endif
#else
#define node_index camera.skip.w  // the view's index in its tree (camera.glsl)
#define VIEW_POINT camera.eye.xyz
#define VIEW_WAY_SCALE way_scale(camera.view)
#define VIEW_AXIS view_axis(camera.view_proj)
#define VIEW_ENTRY camera.clip_plane
#endif
#ifdef OBJECT_MOTION
// Where this view projects the point this frame and projected it last frame (scene.vert,
// scene_batched.geom: the instance's motion, engine/render/object_motion.py).
in vec4 v_clip_now;
in vec4 v_clip_before;
#define SEEN(entity, way) seen_moved(entity, way, v_clip_now, v_clip_before)
#else
#define SEEN(entity, way) seen_at(entity, way)
#endif
// Where this pixel's view ray starts (view_axis.glsl ray_eye: the eye, or for an orthographic
// view the point across from it on the eye's plane), set first thing in main.
vec3 view_eye;
#define VIEW_EYE view_eye

// The variant of each slot: the instance's own (v_slots), or, in a program specialised for a
// batch whose instances all use the same variants, a constant (FIXED_*, defined by
// engine/render/scene_pass.py), so the compiler drops every other case of the switches:
// llvmpipe runs both sides of a branch, even one no pixel takes.
#ifdef FIXED_EMISSIVE
#define SLOT_EMISSIVE FIXED_EMISSIVE
#define SLOT_REFRACT FIXED_REFRACT
#define SLOT_REFLECT FIXED_REFLECT
#else
#define SLOT_EMISSIVE v_slots.x
#define SLOT_REFRACT v_slots.y
#define SLOT_REFLECT v_slots.z
#endif

layout(location = 0) out vec4 out_color;
layout(location = 1) out uint out_surface;  // the entity drawn here
layout(location = 2) out uvec4 out_seen;    // the entity finally seen here, its way, its own motion (way.glsl; reflections overwrite)
layout(location = 3) out uint out_node;
#ifdef SCREEN_REFLECTION
// A root view drawn for screen-space reflections (engine/render/screen_reflections.py): what
// its composite needs to put the screen's reflection in place of the sky's or probe's.  The
// colour is linear in the radiances reflected along the reflected ray (the environment
// reflection's, the reflect slot's), colour = rest + sum of W_i x radiance_i, so with
// W = sum of W_i the composite takes that sum out and puts W x what the screen shows in.
layout(location = 4) out vec4 out_reflect_weight;  // rgb: W (0: nothing reflected); a: the roughness
layout(location = 5) out vec4 out_reflect_added;   // rgb: W x the sky's or probe's radiance; a: the entity's bits 0-10
layout(location = 6) out vec4 out_reflect_normal;  // rgb: the shading normal (world); a: the entity's bits 11-21
vec3 reflect_weight = vec3(0.0);  // W so far: the reflections' weights in the colour, as each step mixes or scales it
vec3 reflect_added = vec3(0.0);   // the sum of each W_i x its radiance, alike

// The colour mixed towards a reflection (weight x radiance) by m, as mix(colour, reflection, m):
// the reflections already in the colour keep 1 - m of their weight.
void mix_reflection(vec3 weight, vec3 radiance, float m) {
    reflect_weight = mix(reflect_weight, weight, m);
    reflect_added = mix(reflect_added, weight * radiance, m);
}
#endif

struct Surface {
    vec3 position;
    vec3 normal;      // unit, facing the viewer (bent by a normal map)
    vec3 geometric_normal;  // unit, facing the viewer: the mesh's own (shadow lookups offset along it)
    vec3 to_eye;      // unit, surface -> eye
    vec3 albedo;
    float alpha;
    float metallic;
    float roughness;
    float occlusion;  // the share of the light from all round that reaches it (material_occlusion; x screen AO)
    float direct_occlusion;  // the share of the lights' direct light (1 but with AmbientOcclusion.direct_light)
    float sun_contact;       // the share of the sun's light past the camera's contact shadows (1 without them)
    vec3 f0;
    vec3 reflect_dir;   // unit, eye ray reflected about the normal
    float reflect_lod;  // sky mip level that matches the pixel footprint of reflect_dir
    vec3 environment_weight;  // the share of the environment's radiance along reflect_dir it reflects (0: a reflect slot does)
    vec3 energy_compensation;  // the lights' GGX highlights x this: the multiple scattering single scattering loses
    float highlight_roughness;  // the roughness the lights' highlights are drawn with (filtered_roughness)
    vec3 refract_dir;
    float refract_lod;
};

// Mip level of a cube map of face size n for a direction that changes across the pixel.
// Computed from derivatives (where the branch is uniform per primitive), not with textureQueryLod,
// whose cube-map answer differs between drivers (llvmpipe's is unusable).
float cube_lod(vec3 direction, float n) {
    float footprint = max(length(dFdx(direction)), length(dFdy(direction))) * n * 0.5;
    return log2(max(footprint, 1e-6));
}

// The sky along ``direction`` from this surface, with its share of the fog out from here
// (fog.glsl: the same as the sky a mirror's composite fills, and the background's; the
// stretch from the eye is fogged once the pixel's colour is made).
vec3 sample_environment(vec3 direction, float lod, float roughness) {
    return fog_sky(textureLod(sky_map, direction, lod + roughness_lod_bias(roughness)).rgb, v_world_pos, direction);
}

// The probe uniforms, box projection, the level a roughness reads and probe blending.
#include "probe.glsl"

// --- Environment specular --------------------------------------------------------------
// What a surface without a reflect slot (no Reflective, not a mirror or portal) reflects of
// the light from all round, as every engine's default material does (Unity's and Godot's sky
// and probe reflections, three.js's envMap): the radiance along the reflected ray, blurred by
// the roughness (the sky cube's mips), times the split-sum's share (environment_share: f0 A + B
// and multiple scattering), times the material's environment_reflection (v_reflect.x of such
// an instance).  The ambient diffuse takes 1 - that share (the energy the reflection took, as
// Filament and three.js do).
//
// The radiance is the sky's; inside reflection probes' influence boxes it is normalised by the
// light there (a cube map scaled by the diffuse light at the point over its own, as Blender's
// EEVEE normalises its sphere probes by its volume probes' harmonics): the sky's share of the
// boxes' blend keeps the sky, each box's share is the sky times that box's irradiance over
// the sky's along the ray, so a dim room's floor reflects a dim sky, not the daylight.  (Sharp reflections of a
// probe's capture: Reflective("cube").)  A world with no Skybox has a flat background, not
// its hemisphere, in the cube: there the radiance is E(r) / pi, the hemisphere and the boxes
// blurred to their harmonics (lights.counts.z, views.lights_block).
//
// An object that samples probes (the ENVIRONMENT_PROBE builds: probe_rules.probe_blend, the
// influence boxes holding its position blended, the sky taking the rest, as Unity's and
// HDRP's probes serve every renderer in their volumes; glass and a cube Reflective their own)
// reflects their captures, sharp and box-projected, instead: the sky's normalisation above is
// for what samples none (a floor whose middle no box holds, a probe with no capture yet).
vec3 environment_radiance(Surface s, AmbientBoxes boxes) {
    vec3 r = s.reflect_dir;
#ifdef ENVIRONMENT_PROBE
    return probe_radiance(s.position, r, s.reflect_lod + log2(probe_face_size / sky_face_size), s.roughness);
#else
    vec3 sky = textureLod(sky_map, r, s.reflect_lod + roughness_lod_bias(s.roughness)).rgb;
    vec3 sky_e = sky_irradiance(r);
    vec3 boxes_e = boxes_irradiance(boxes, r);
    // A floor under the sky's irradiance along the ray: a quarter of its mean (where the sky
    // is black below, a box's light is not divided by nothing).
    vec3 floor_e = max(0.25 * 0.2820948 * lights.sky_sh[0].rgb, vec3(1e-4));
    vec3 radiance = lights.counts.z != 0 ? (sky_e * boxes.sky + boxes_e) / PI
                                         : sky * (boxes.sky + boxes_e / max(sky_e, floor_e));
    return fog_sky(max(radiance, vec3(0.0)), s.position, r);
#endif
}

// The share of the light from all round a surface of reflectance f0 reflects, from the split
// sum's (A, B): single scattering, f0 A + B, and the light rough GGX loses to its microfacets'
// shadowing (1 - A - B) given back as multiple scattering would (Fdez-Aguera, "A Multiple-
// Scattering Microfacet Model for Real-Time Image-based Lighting", 2019; three.js's
// computeMultiscattering): a white metal under an even sky shows the sky at any roughness.
vec3 environment_share(vec3 f0, vec2 ab) {
    vec3 single = f0 * ab.x + ab.y;
    float lost = 1.0 - ab.x - ab.y;
    vec3 average = f0 + (1.0 - f0) / 21.0;  // Schlick's Fresnel averaged over the hemisphere
    return single + single * average / (1.0 - lost * average) * lost;
}

// What the lights' own GGX highlights are multiplied by to give back the light single
// scattering loses (Kulla and Conty, "Revisiting Physically Based Shading at Imageworks",
// 2017, in Filament's form: 1 + f0 (1 / (A + B) - 1), A + B the split sum's share of a white
// metal): a rough metal's highlight is as bright as the environment_share its reflection of
// the sky has, instead of losing up to a third of its light at roughness 1.  A dielectric's
// (f0 0.04) grows by at most a few percent.
vec3 energy_compensation(vec3 f0, vec2 ab) {
    return 1.0 + f0 * (1.0 / max(ab.x + ab.y, 1e-3) - 1.0);
}

// Geometric specular anti-aliasing (Kaplanyan, Hill, Patney and Lefohn, "Filtering
// Distributions of Normals for Shading Antialiasing", HPG 2016; Tokuyoshi and Kaplanyan,
// "Improved Geometric Specular Antialiasing", i3D 2019; Filament's normalFiltering): where the
// normal turns across a pixel (a small or far curved object, a normal map's bumps) a tight
// highlight lands on one pixel or none, so it flickers as the object moves.  The GGX lobe
// is widened by the normal's variance over the pixel, from its screen derivatives: alpha^2
// grows by 2 x SPECULAR_AA_VARIANCE x (|dn/dx|^2 + |dn/dy|^2), at most SPECULAR_AA_THRESHOLD.
// The variance is a third of Filament's 0.15: against an 8x supersampled reference
// (tests/test_specular_antialiasing.py) 0.05 keeps small spheres' highlight energy within 6%
// at every sub-pixel offset (one sample a pixel: 14-28% low, swinging 14% as they move) with
// no more per-pixel error than one sample has; 0.15 overshot by 7-10% and doubled that error.
// Only the lights' highlights: the environment's reflection is filtered by its mip level,
// which the reflected ray's derivatives choose.
const float SPECULAR_AA_VARIANCE = 0.05;
const float SPECULAR_AA_THRESHOLD = 0.2;

float filtered_roughness(float roughness, vec3 n) {
    vec3 du = dFdx(n), dv = dFdy(n);
    float kernel = min(2.0 * SPECULAR_AA_VARIANCE * (dot(du, du) + dot(dv, dv)), SPECULAR_AA_THRESHOLD);
    float alpha = roughness * roughness;
    return sqrt(sqrt(clamp(alpha * alpha + kernel, 0.0, 1.0)));
}

// Whether the surface's light holds the environment reflection: a surface without a reflect
// slot's, by its material's share (v_reflect.x: environment_reflection,
// material_dispatch.choose_material); and with a metallic-roughness map a sky or probe
// Reflective's too, whole, in the light its slot's reflection mixes with, so the parts the
// map says are not metal keep the light a plain material of theirs has (mapped_reflection).
bool environment_reflected() {
    bool reflected = SLOT_REFLECT == REFLECT_NONE;
#ifdef METALLIC_ROUGHNESS_MAP
    reflected = reflected || SLOT_REFLECT == REFLECT_SKYBOX || SLOT_REFLECT == REFLECT_CUBE;
#endif
    return reflected;
}

// The environment's specular light at the surface (0 where a reflect slot reflects instead).
// Where something hides part of the sky from the point (the occlusion map, screen-space
// AO), the reflection is occluded by Lagarde and de Rousiers' specular occlusion ("Moving
// Frostbite to Physically Based Rendering", 2014; Filament's computeSpecularAO): a narrow
// lobe seen head on leaves the occluders aside and keeps more than the diffuse light's share,
// a grazing or rough one as little; it is 1 where nothing occludes.  Faded where a normal map
// turns the reflected ray below the mesh's own surface (Marmoset's horizon fade).
float specular_occlusion(float nv, float occlusion, float roughness) {
    float alpha = roughness * roughness;
    return clamp(pow(nv + occlusion, exp2(-16.0 * alpha - 1.0)) - 1.0 + occlusion, 0.0, 1.0);
}

#ifdef SCREEN_REFRACTION
#include "screen_refraction.glsl"

// What the view drew along the ray from the refracting surface ``s`` at ``origin`` along unit
// ``direction``, where the march finds it (screen_refraction.glsl), over ``otherwise`` (the
// probe's or sky's radiance) by the find's confidence: what it lets through, and what it
// reflects (a refracting surface's own screen-space reflection: HDRP's transparent SSR).
// (spread: the radians the ray turns from one pixel to the next, from its cube map's mip level
// ``lod`` for a face of ``face_size`` texels: cube_lod)
float ray_spread(float lod, float face_size) {
    return exp2(lod) * 2.0 / max(face_size, 1.0);
}

vec3 screen_found(Surface s, vec3 origin, vec3 direction, float spread, vec3 otherwise) {
    float uncovered;
    vec4 found = screen_refraction(origin, direction, s.roughness, spread, uncovered);
    if (found.a <= 0.0) return otherwise;
    vec3 drawn = found.rgb;
#ifdef FOG
    // The view fogged what it drew along the whole way to it; this surface's own fog (main's
    // fog_view) is put over what it lets through and reflects, so the stretch to the surface
    // is taken out of the find first (exactly so where the ray runs on as the eye's).
    FogDepth kept = exp(-fog_depth(fog_start(VIEW_EYE, VIEW_ENTRY, s.position), s.position));
    drawn = max(drawn - fog_view(vec3(0.0), VIEW_EYE, VIEW_ENTRY, s.position), vec3(0.0)) / max(kept, FogDepth(1e-4));
#endif
    drawn += otherwise * uncovered;  // (a reflection level's sky under what it drew there)
    return mix(otherwise, drawn, found.a);
}
#endif

vec3 environment_light = vec3(0.0);  // what environment_specular added: a refraction keeps it whole
#ifdef SCREEN_REFLECTION
vec3 environment_reflect_weight = vec3(0.0);  // ... and its part of reflect_weight and reflect_added
vec3 environment_reflect_added = vec3(0.0);
#endif

vec3 environment_specular(Surface s, AmbientBoxes boxes) {
    float horizon = clamp(1.0 + dot(s.reflect_dir, s.geometric_normal), 0.0, 1.0);
    float occlusion = specular_occlusion(max(dot(s.normal, s.to_eye), 0.0), s.occlusion, s.roughness);
    vec3 weight = s.environment_weight * (occlusion * horizon * horizon);
    vec3 radiance = environment_radiance(s, boxes);
#ifdef SCREEN_REFRACTION
    // (glass reflects what its view drew)
    radiance = screen_found(s, s.position, s.reflect_dir, ray_spread(s.reflect_lod, sky_face_size), radiance);
#endif
    environment_light = weight * radiance;
#ifdef SCREEN_REFLECTION
    environment_reflect_weight = weight;
    environment_reflect_added = environment_light;
    reflect_weight += weight;  // (added to the colour)
    reflect_added += environment_light;
#endif
    return environment_light;
}

// The lights' highlights (their GGX specular light), summed apart from their diffuse light:
// what a see-through material with Material.blend "transparent" keeps whole (main).
vec3 highlight_light = vec3(0.0);

#ifdef CLEARCOAT
// The clear coat (Material.clearcoat, glTF's KHR_materials_clearcoat, as Filament's and
// three.js's): a colourless layer of index 1.5 (f0 0.04) over the material, GGX with a
// roughness of its own, on the mesh's own normal (a normal map's bumps stay under the
// varnish).  The lights' loops sum its highlights here; main adds its reflection of the light
// from all round (coat_environment) and lays both over the material, which keeps
// 1 - clearcoat x F(n.v) of its light (glTF's layering).  Only in the CLEARCOAT builds (its
// batch's material has a coat): llvmpipe would run it for every pixel otherwise.
uniform vec2 clearcoat;       // x: its batch's Material.clearcoat, y: clearcoat_roughness
vec3 coat_light = vec3(0.0);  // the coat's highlights of the lights, summed
vec3 coat_normal = vec3(0.0, 0.0, 1.0);  // unit, facing the viewer (main sets it before the lights)
float coat_roughness = 0.0;   // clearcoat.y widened where the normal turns (filtered_roughness)
#endif

#ifdef SHEEN
// The sheen (Material.sheen_color, sheen_roughness; glTF's KHR_materials_sheen, as Filament
// and three.js draw it): cloth's or velvet's microfibres scattering light back at the rims,
// the "Charlie" distribution (Estevez and Kulla 2017) with Neubelt's visibility: the
// formulas and their albedo E(n.v), the share the layer takes from the material under it,
// are engine/render/environment_brdf.py's (its table in the blue of the BRDF rows).  The
// lights' loops sum its light here; main lays it, and its reflection of the light from all
// round (sheen_environment), over the material.  Only in the SHEEN builds.
uniform vec4 sheen;            // rgb: its batch's Material.sheen_color, a: sheen_roughness
vec3 sheen_light = vec3(0.0);  // the lights' sheen (D V n.l x arriving), summed
const float SHEEN_MIN_ALPHA = 0.002;  // environment_brdf.py's

// D(h) V(l, v) n.l for unit n, l and v: the sheen lobe's share of light arriving along l.
float sheen_lobe(vec3 n, vec3 l, vec3 v) {
    float nl = max(dot(n, l), 0.0), nv = max(dot(n, v), 1e-4);
    vec3 h = normalize(l + v);
    float alpha = max(sheen.a * sheen.a, SHEEN_MIN_ALPHA);
    float sin2 = max(1.0 - dot(n, h) * dot(n, h), 0.0);
    float d = (2.0 + 1.0 / alpha) * pow(sin2, 0.5 / alpha) / (2.0 * PI);
    return d * nl / max(4.0 * (nl + nv - nl * nv), 1e-6);
}
#endif

// Anisotropic highlights and a thin film (their code only in the ANISOTROPY and IRIDESCENCE builds).
#include "anisotropic_ggx.glsl"
#include "thin_film.glsl"

// Light through mirrors and portals (its loop only in the VIRTUAL_LIGHTS builds).
// The heights' shadows in the PARALLAX builds (parallax.glsl, below): a directional light's
// arriving light times the share the heights let through, PARALLAX_LIT(l) after it.  Not the
// lamps' (each a march of its own: in the normal_maps benchmark the sun's and a lamp's
// together, 8 steps each, made llvmpipe's frame 2.47 x a plain ground's, the view's march
// alone 1.64 x, the sun's added in 6 steps 2.0 x).
#ifdef PARALLAX
float parallax_shadow(vec3 l);
#define PARALLAX_LIT(l) * parallax_shadow(l)
#else
#define PARALLAX_LIT(l)
#endif
#include "virtual_lights.glsl"

#ifdef CLEARCOAT
// The coat's reflection of the light from all round, as environment_specular's (the sky or
// the probes, by the split sum's share for f0 0.04, occluded as it is) along the ray the
// coat's own normal reflects, blurred by the coat's roughness.
vec3 coat_environment(Surface s, AmbientBoxes boxes, float nv) {
    Surface coat = s;
    coat.normal = coat_normal;
    coat.roughness = clearcoat.y;
    coat.reflect_dir = reflect(-s.to_eye, coat_normal);
    coat.reflect_lod = cube_lod(coat.reflect_dir, sky_face_size);
    float occlusion = specular_occlusion(nv, s.occlusion, clearcoat.y);
    vec3 share = environment_share(vec3(0.04), environment_brdf(clearcoat.y, nv));
    return environment_radiance(coat, boxes) * share * (occlusion * float(lights.counts.w));
}
#endif

#ifdef SHEEN
// The sheen's reflection of the light from all round: the sky's or probes' radiance along the
// reflected ray blurred by the sheen's roughness (Filament's approximation of the sheen's
// own prefiltered light) x its albedo at this angle, occluded as the light from all round is.
vec3 sheen_environment(Surface s, AmbientBoxes boxes, float albedo) {
    Surface layer = s;
    layer.roughness = sheen.a;
    return environment_radiance(layer, boxes) * (albedo * s.occlusion * float(lights.counts.w));
}
#endif

#ifdef DIFFUSE_TRANSMISSION
// Diffuse transmission (Material.diffuse_transmission; glTF's KHR_materials_diffuse_transmission):
// a thin surface lets its share of the light it scatters through, so what lights its back
// (the sun, the lamps and the light from all round behind it, with the back's shadows: the
// lookups again with the normal turned) lights its front too, in its own colour, evenly (the
// back's Lambert); its front scatters the rest.  Only in the DIFFUSE_TRANSMISSION builds.
uniform vec4 diffuse_transmission;  // rgb: its batch's Material.diffuse_transmission_color, a: its share
#endif

// Point light i's light at the surface (its diffuse and highlight; the clear coat's, sheen's
// and highlights' sums beside it).  ``rectangle``: a constant at each call (direct_lighting),
// so each build keeps one way: a rectangle's integrals (rect_lights.glsl) only in the loop
// over the rectangles, not paid by every lamp (llvmpipe runs a branch's body for every pixel:
// eight lamps, one of them a panel, cost a frame 2.3 x eight points when every lamp ran it).
vec3 lamp_light(int i, bool rectangle, Surface s, vec3 diffuse, vec4 point_lit
#ifdef DIFFUSE_TRANSMISSION
                , vec3 through, vec4 point_behind
#endif
#ifdef SUBSURFACE
                , vec4 point_under
#endif
                ) {
    vec3 lit = vec3(0.0);
    vec3 d = lights.point_pos[i].xyz - s.position;
    float dist = length(d);
    vec3 l = d / max(dist, 1e-4);
    float nl = max(dot(s.normal, l), 0.0);
    float falloff = lamp_falloff(i, dist, l);
    // Its colour as it arrives: dimmed channel by channel by a water's body on its way.
    vec3 color = lights.point_color[i].rgb * water_light(s.position, l, dist);
    vec3 face = vec3(1.0);   // a rectangle's image on its face as its diffuse light sees it (rect_face)
#ifdef RECT_LIGHTS
    // A rectangle (rect_lights.glsl): its light from all of it above the horizon, its
    // radiance (the light's over its area) for the inverse square, n.l its form factor.
    RectLight rect = rect_light(lights.point_rect_u[i], lights.point_rect_v[i], d);
    float centre_nl = nl;
    if (rectangle) {
        falloff = lamp_fade(i, dist, l) * rect.radiance;
        nl = rect_form_factor(rect, s.normal, face);
    }
#endif
#ifdef CAUSTIC_LAMPS
    // The light a water over the point gathers of it (caustics.glsl caustic_lamp_light).
    for (int j = 0; j < 4; ++j) {
        if (caustic_lamps[j] == i) falloff *= lamp_caustic[j];
    }
#endif
#if defined(SCREEN_OCCLUSION) && defined(CONTACT_LAMPS)
    // Its contact shadows' channel, if it has them (its cookie row's w: the channel + 1).
    int contact_channel = int(lights.point_cookie_v[i].w + 0.5) - 1;
    if (contact_channel >= 0) falloff *= lamp_contact[contact_channel];
#endif
#ifdef SPOT_COOKIES
    vec3 cookie_at = cookie_place(lights.point_cookie_u[i], lights.point_cookie_v[i], lights.point_spot[i], l);
    vec2 cookie_dx = cookie_derivative(dFdx(cookie_at.xy)), cookie_dy = cookie_derivative(dFdy(cookie_at.xy));
#endif
#ifdef DIFFUSE_TRANSMISSION
    float behind = max(-dot(s.normal, l), 0.0);
    vec3 behind_face = vec3(1.0);
#ifdef RECT_LIGHTS
    if (rectangle) behind = rect_form_factor(rect, -s.normal, behind_face);
#endif
    if (behind > 0.0 && falloff > 0.0) {
#ifdef SPOT_COOKIES
        vec3 behind_cookie = cookie_light(cookie_at, cookie_dx, cookie_dy);
#else
        const vec3 behind_cookie = vec3(1.0);
#endif
        lit += through * behind * color * behind_cookie * behind_face * falloff
               * point_shadow(i, point_behind);
    }
#endif
#ifdef SUBSURFACE
    // The diffuse light, scattered under the surface (subsurface.glsl): past the terminator too
    // (a rectangle's form factor is its n.l: its light wraps no further).
    if (falloff > 0.0) {
#ifdef SPOT_COOKIES
        vec3 under_cookie = cookie_light(cookie_at, cookie_dx, cookie_dy);
#else
        const vec3 under_cookie = vec3(1.0);
#endif
        lit += diffuse * face * subsurface_diffuse(rectangle ? nl : dot(s.normal, l), point_shadow(i, point_lit),
                                                   point_shadow(i, point_under))
               * color * under_cookie * falloff;
    }
#endif
    if (nl > 0.0 && falloff > 0.0) {
#ifdef SPOT_COOKIES
        vec3 cookie = cookie_light(cookie_at, cookie_dx, cookie_dy);
#else
        const vec3 cookie = vec3(1.0);
#endif
        vec3 arriving = color * cookie * falloff * point_shadow(i, point_lit);
#ifdef ANISOTROPY
        vec3 highlight = anisotropic_specular(s.normal, l, s.to_eye, s.f0) * (nl * s.energy_compensation);
#else
#ifdef RECT_LIGHTS
        vec3 highlight = (rectangle ? rect_highlight(rect, s.normal, s.to_eye, s.f0, s.highlight_roughness)
                                    : sphere_highlight(s.normal, s.to_eye, s.reflect_dir, d, lights.point_color[i].w,
                                                       s.f0, s.highlight_roughness)) * s.energy_compensation;
#else
        vec3 highlight = sphere_highlight(s.normal, s.to_eye, s.reflect_dir, d, lights.point_color[i].w, s.f0,
                                          s.highlight_roughness) * s.energy_compensation;
#endif
#endif
#ifdef SUBSURFACE
        lit += highlight * arriving;  // (its diffuse light above)
#else
        lit += (diffuse * nl * face + highlight) * arriving;
#endif
        highlight_light += highlight * arriving;
#ifdef CLEARCOAT
#ifdef RECT_LIGHTS
        vec3 coat = rectangle ? rect_highlight(rect, coat_normal, s.to_eye, vec3(0.04), coat_roughness)
                              : sphere_highlight(coat_normal, s.to_eye, reflect(-s.to_eye, coat_normal), d,
                                                 lights.point_color[i].w, vec3(0.04), coat_roughness);
#else
        vec3 coat = sphere_highlight(coat_normal, s.to_eye, reflect(-s.to_eye, coat_normal), d,
                                     lights.point_color[i].w, vec3(0.04), coat_roughness);
#endif
        coat_light += coat * arriving;
#endif
#ifdef SHEEN
        float sheen_share = 1.0;  // a rectangle's: its form factor for n.l towards its centre
#ifdef RECT_LIGHTS
        if (rectangle) sheen_share = nl / max(centre_nl, 1e-3);
#endif
        sheen_light += sheen_lobe(s.normal, l, s.to_eye) * (arriving * face * sheen_share);
#endif
    }
    return lit;
}

vec3 direct_lighting(Surface s, AmbientBoxes boxes) {
    vec3 diffuse = s.albedo * (1.0 - s.metallic) / PI;
#ifdef DIFFUSE_TRANSMISSION
    vec3 through = diffuse_transmission.rgb * (diffuse_transmission.a * (1.0 - s.metallic) / PI);
    diffuse *= 1.0 - diffuse_transmission.a;
#endif
    // E(n) x albedo x (1 - metallic) / pi, less what the environment's reflection took, and that reflection
#ifdef LIGHTMAP
    vec3 total = lightmap_irradiance() * diffuse * s.occlusion * (1.0 - s.environment_weight);  // (baked)
#else
#ifdef SUBSURFACE
    subsurface_bands_begin();   // the light from all round scattered under it too (subsurface.glsl)
#endif
    vec3 total = ambient_irradiance(boxes, s.normal) * diffuse * s.occlusion * (1.0 - s.environment_weight);
#ifdef SUBSURFACE
    subsurface_bands_end();
#endif
#endif
#ifdef DIFFUSE_TRANSMISSION
    total += ambient_irradiance(boxes, -s.normal) * through * s.occlusion;  // the light from all round behind
#endif
    if (environment_reflected()) total += environment_specular(s, boxes);
    // Under a water's body (Water.fog_density) the light from all round comes down through the
    // water over the point, the suns' along their way (fog.glsl water_skylight, water_light).
    total *= water_skylight(s.position);
#ifdef SCREEN_OCCLUSION
    vec3 ambient = total;  // the direct light, summed apart, takes its own share of the occlusion
    total = vec3(0.0);
#endif
    // The maps looked up before the loops (shadows.glsl); none for an instance that receives
    // no shadow (MeshRef.receives_shadows: its code's NO_RECEIVE_BIT, visibility.glsl).
    bool shadowed = !receives_no_shadow(v_tint.w);
    vec4 directional_lit = shadowed ? directional_shadows(s.position, s.geometric_normal) : vec4(1.0);
#ifdef SEE_THROUGH_SHADOWS
    // The share of the suns' light see-through things over the point let through (shadows.glsl).
    if (shadowed) directional_lit *= see_through_shadows(s.position, s.geometric_normal);
#endif
#ifdef CAUSTICS
    // The suns' light through a rippled water gathered by its waves (caustics.glsl), over the
    // pixel's footprint (taken here, in uniform control flow: the caustic returns early off the water).
    float caustic_footprint = max(length(dFdx(s.position)), length(dFdy(s.position)));
    // Through each water the batch reaches into (caustic_waters; a point under two bodies at once
    // takes both's).
    for (int i = 0; i < lights.counts.x; ++i) {
        for (int k = 0; k < MAX_CAUSTIC_WATERS; ++k) {
            if (caustic_waters[k] < 0) break;
            directional_lit[i] *= caustic_light(caustic_waters[k], s.position, -lights.directional_dir[i].xyz,
                                                caustic_footprint);
        }
    }
#ifdef CAUSTIC_LAMPS
    // ... and the lamps' over them (the block's caustic_lamps: lamps over a held water).
    for (int j = 0; j < 4; ++j) {
        int lamp = caustic_lamps[j];
        if (lamp < 0) break;
        lamp_caustic[j] = 1.0;
        for (int k = 0; k < MAX_CAUSTIC_WATERS; ++k) {
            if (caustic_waters[k] < 0) break;
            lamp_caustic[j] *= caustic_lamp_light(caustic_waters[k], s.position, lights.point_pos[lamp].xyz,
                                                  lights.point_color[lamp].w, lights.point_rect_u[lamp],
                                                  lights.point_rect_v[lamp], caustic_footprint);
        }
    }
#endif
#endif
#ifdef SCREEN_OCCLUSION
    // The camera's contact shadows dim the sun's light (its slot's w: lights.glsl).
    vec4 sun_slots = max(vec4(lights.directional_dir[0].w, lights.directional_dir[1].w, lights.directional_dir[2].w,
                              lights.directional_dir[3].w), 0.0);
    directional_lit *= mix(vec4(1.0), vec4(s.sun_contact), sun_slots);
#endif
#ifdef CLOUD_SHADOWS
    // A CloudLayer's shadows on the sun's and the moons' light (their slots' w, not 0; clouds.glsl),
    // on every surface (a cloud's shadow is no shadow map's: receives_shadows does not turn it off).
    vec4 sun_clouds = vec4(1.0);
    for (int i = 0; i < lights.counts.x; ++i) {
        if (lights.directional_dir[i].w != 0.0) sun_clouds[i] = cloud_shadow(s.position, -lights.directional_dir[i].xyz);
    }
    directional_lit *= sun_clouds;
#define CLOUDED(i) * sun_clouds[i]
#else
#define CLOUDED(i)
#endif
    vec4 point_lit = shadowed ? point_shadows(s.position, s.geometric_normal) : vec4(1.0);
#ifdef DIFFUSE_TRANSMISSION
    vec4 directional_behind = shadowed ? directional_shadows(s.position, -s.geometric_normal) : vec4(1.0);
    vec4 point_behind = shadowed ? point_shadows(s.position, -s.geometric_normal) : vec4(1.0);
#endif
#ifdef SUBSURFACE
    // The scattered share's shadows (subsurface.glsl): the lamps' slots here, the suns' in their loop.
    vec4 point_under = shadowed ? subsurface_point_shadows(s.position, s.geometric_normal) : vec4(1.0);
#endif
    for (int i = 0; i < lights.counts.x; ++i) {
        vec3 l = -lights.directional_dir[i].xyz;
        float nl = max(dot(s.normal, l), 0.0);
        // Its colour as it arrives: dimmed channel by channel by a water's body on its way.
        vec3 sun_color = lights.directional_color[i].rgb * water_light(s.position, l, 1e30);
#ifdef DIFFUSE_TRANSMISSION
        total += through * (max(-dot(s.normal, l), 0.0) * directional_behind[i] CLOUDED(i)) * sun_color;
#endif
#ifdef SUBSURFACE
        float under = directional_lit[i];  // (where the light reaches the point, its own shadow)
        if (shadowed && dot(s.geometric_normal, l) < 0.0) {
            vec3 under_normal;
            vec3 under_at = subsurface_shadow_point(s.position, s.geometric_normal, l, under_normal);
            under = directional_shadow(i, under_at, under_normal, l) CLOUDED(i);
#ifdef SCREEN_OCCLUSION
            under *= mix(1.0, s.sun_contact, max(lights.directional_dir[i].w, 0.0));
#endif
        }
        total += diffuse * subsurface_diffuse(dot(s.normal, l), directional_lit[i] PARALLAX_LIT(l),
                                              under PARALLAX_LIT(l)) * sun_color;
#endif
        if (nl > 0.0) {
            vec3 arriving = sun_color * nl * directional_lit[i] PARALLAX_LIT(l);
#ifdef ANISOTROPY
            vec3 highlight = anisotropic_specular(s.normal, l, s.to_eye, s.f0) * s.energy_compensation;
#else
            vec3 highlight = ggx_specular(s.normal, l, s.to_eye, s.f0, s.highlight_roughness) * s.energy_compensation;
#endif
#ifdef SUBSURFACE
            total += highlight * arriving;  // (its diffuse light above)
#else
            total += (diffuse + highlight) * arriving;
#endif
            highlight_light += highlight * arriving;
#ifdef CLEARCOAT
            coat_light += ggx_specular(coat_normal, l, s.to_eye, vec3(0.04), coat_roughness)
                          * (max(dot(coat_normal, l), 0.0) * directional_lit[i]) * sun_color
                          PARALLAX_LIT(l);
#endif
#ifdef SHEEN
            sheen_light += sheen_lobe(s.normal, l, s.to_eye) * directional_lit[i] * sun_color
                           PARALLAX_LIT(l);
#endif
        }
    }
    for (int i = 0; i < lights.counts.y; ++i) {
#ifdef RECT_LIGHTS
        if (lights.point_rect_u[i].w != 0.0) continue;   // (a rectangle: in the loop below)
#endif
        total += lamp_light(i, false, s, diffuse, point_lit
#ifdef DIFFUSE_TRANSMISSION
                            , through, point_behind
#endif
#ifdef SUBSURFACE
                            , point_under
#endif
                            );
    }
#ifdef RECT_LIGHTS
    for (int k = 0; k < MAX_RECT_LIGHTS; ++k) {   // the rectangles' slots (light_rules: the first by slot)
        int i = lights.rect_slots[k / 4][k % 4];
        if (i < 0) break;
        total += lamp_light(i, true, s, diffuse, point_lit
#ifdef DIFFUSE_TRANSMISSION
                            , through, point_behind
#endif
#ifdef SUBSURFACE
                            , point_under
#endif
                            );
    }
#endif
#ifdef VIRTUAL_LIGHTS
    total += virtual_lighting(s.position, s.normal, s.geometric_normal, s.to_eye, diffuse, s.f0, s.highlight_roughness,
                              s.energy_compensation, shadowed);
#endif
#ifdef SCREEN_OCCLUSION
    total = ambient + total * s.direct_occlusion;
#endif
    return total;
}

#include "normal_map.glsl"
#include "parallax.glsl"
#include "material_maps.glsl"
#ifdef NORMAL_MAP
// The directions in which U and V grow across the surface, from screen derivatives of the
// position and the UVs (a cotangent frame: Schüler, "Normal Mapping Without Precomputed
// Tangents", 2013), so meshes need no tangent attribute.  Only this build of the program
// computes it (engine/render/scene_pass.py): a batch with a normal map.
// ``uv``: the plain UVs (the frame's); the map is read there, or where a parallax shift
// moves it (PARALLAX builds), filtered by the plain UVs' derivatives.
vec3 mapped_normal(vec3 n, vec3 p, vec2 uv, float scale) {
    vec3 dp1 = dFdx(p), dp2 = dFdy(p);
    vec2 duv1 = dFdx(uv), duv2 = dFdy(uv);
    // (those sums are the gradients times dot(n, dp1 x dp2): negative in a mirror's view, whose
    // screen is the world turned, so undone by its sign; and a double-sided back face's frame
    // is turned round with its normal, so its bent normal is minus the front's, as glTF's)
    float handed = (dot(n, cross(dp1, dp2)) < 0.0 ? -1.0 : 1.0) * (gl_FrontFacing ? 1.0 : -1.0);
    vec3 dp2perp = cross(dp2, n) * handed, dp1perp = cross(n, dp1) * handed;
    vec3 t = dp2perp * duv1.x + dp1perp * duv2.x;  // the gradients of u and of v in the surface
    vec3 b = dp2perp * duv1.y + dp1perp * duv2.y;
    if (dot(t, t) < 1e-30 || dot(b, b) < 1e-30) return n;  // UVs that do not vary here: flat
#ifdef PARALLAX
    return bent_normal(normalize(t), normalize(b), n, uv PARALLAX_SHIFT, duv1, duv2, scale);
#else
    // (implicit derivatives: nothing before it leaves a pixel out.  With the explicit ones,
    // llvmpipe taking a GPU's branches, SPECULUM_AS_GPU=1, shaded a decal's cut mesh 13 of
    // 255 off the quad it was cut from, tests/test_decals.py; the implicit lookup agrees.)
    return bent_by(normalize(t), normalize(b), n, texture(normal_map, uv).xyz, scale);
#endif
}
#endif

// --- Reflect slot ---------------------------------------------------------------------
// The part of the colour that is reflected light (the lights' highlights, the environment's
// reflection, a reflect slot's): what a see-through Material.blend "transparent" keeps whole
// (main).  A slot mixes it as it mixes the colour.
vec3 kept_light = vec3(0.0);

vec3 reflect_skybox(vec3 color, Surface s) {
    // Sample the sky along reflect(view, normal); mix by the instance's amount.
    vec3 radiance = sample_environment(s.reflect_dir, s.reflect_lod, s.roughness);
#ifdef SCREEN_REFLECTION
    mix_reflection(v_tint.rgb * s.occlusion, radiance, v_reflect.x);
#endif
    kept_light = mix(kept_light, radiance * v_tint.rgb * s.occlusion, v_reflect.x);
    return mix(color, radiance * v_tint.rgb * s.occlusion, v_reflect.x);
}

vec3 reflect_probe(vec3 color, Surface s) {
    // A cube map captured around the object (engine/render/probes.py), blurred by roughness
    // and weighted by GGXReflect with the material's F0: a metal tints what it reflects
    // (brass is golden), a dielectric reflects most at grazing angles.
    vec3 radiance = probe_radiance(s.position, s.reflect_dir, s.reflect_lod, s.roughness);
    vec3 reflected = ggx_reflect(s.normal, s.reflect_dir, s.to_eye, radiance * s.occlusion, s.f0, s.roughness);
#ifdef SCREEN_REFLECTION
    // (ggx_reflect is the radiance times a factor: that factor, of a radiance of 1.)
    mix_reflection(ggx_reflect(s.normal, s.reflect_dir, s.to_eye, vec3(s.occlusion), s.f0, s.roughness) * v_tint.rgb,
                   radiance, v_reflect.x);
#endif
    kept_light = mix(kept_light, reflected * v_tint.rgb, v_reflect.x);
    return mix(color, reflected * v_tint.rgb, v_reflect.x);
}

vec3 apply_reflect(uint variant, vec3 color, Surface s) {
    switch (variant) {
        case REFLECT_SKYBOX:
            return reflect_skybox(color, s);
        case REFLECT_CUBE:
            return reflect_probe(color, s);
        case REFLECT_PORTAL:
            // A portal's closed look (no working partner): flat, unlit.  An open portal's view,
            // or its fallback where it has none, is composited over it by the view tree.
            return v_tint.rgb;
        case REFLECT_PLANAR:
            // A mirror keeps its own shading here; the view tree blends its reflection over
            // these pixels once it has been rendered, or its fallback (the probe's or the
            // sky's reflection) where it has no view (engine/render/mirror_passes.py).
        default:
            return color;
    }
}

// --- Refract slot ---------------------------------------------------------------------
// A solid ball (Refractive(solid=True)): the eye ray refracted in at the surface (Snell's
// law), carried along the chord through the sphere and refracted out where it leaves: the
// two-interface ray trace of a ball lens, in closed form.  With n the unit normal where the
// ray enters and d the unit direction inside, the chord ends where the normal is
// n - 2 (d.n) d (the sphere's radius drops out: only the exit's direction is needed).  Exact
// for a sphere, an approximation for any other mesh (each point taken as on the sphere
// its normal implies).  Rays entering a sphere always leave it (the exit angle equals the
// entry angle), so there is no total internal reflection to handle.
vec3 solid_sphere_exit(vec3 incident, vec3 n, float ior) {
    vec3 inside = refract(incident, n, 1.0 / ior);
    vec3 exit_normal = n - 2.0 * dot(inside, n) * inside;  // outward, where the chord leaves
    return refract(inside, -exit_normal, ior);
}

#ifdef DISPERSION
uniform float dispersion;  // its batch's Refractive.dispersion (glTF's KHR_materials_dispersion: 20 / Abbe number)
#endif

#ifdef SCREEN_REFRACTION
flat in vec3 v_centre;  // the instance's origin in the world (scene.vert)
#endif

// Where a refracted ray leaves the surface towards what lies behind: where it enters, or a
// solid ball's ray where it leaves the ball, 2 (c - p).d along its way in (the chord of the
// sphere about the instance's origin c through the point p: exact for a sphere mesh).  Only
// the screen's march needs the place; the probe's and sky's images are read by direction.
vec3 refraction_origin(Surface s, float ior, bool solid) {
#ifdef SCREEN_REFRACTION
    if (solid) {
        vec3 inside = refract(-s.to_eye, s.normal, 1.0 / ior);
        return s.position + inside * max(2.0 * dot(v_centre - s.position, inside), 0.0);
    }
#endif
    return s.position;
}

// What lies behind along a refracted ray: the probe's capture when one serves the object,
// else the sky; in SCREEN_REFRACTION builds (Refractive.screen, a view tree's views) what the
// view drew there where the ray finds it (screen_refraction.glsl), the probe's or sky's
// image where it does not, faded between by the find's confidence.
vec3 refracted_light(Surface s, vec3 origin, vec3 direction, float lod) {
    vec3 behind = probe_face_size > 0.0 ? probe_radiance(s.position, direction, lod, s.roughness)
                                        : sample_environment(direction, lod, s.roughness);
#ifdef SCREEN_REFRACTION
    float spread = ray_spread(lod, probe_face_size > 0.0 ? probe_face_size : sky_face_size);
    behind = screen_found(s, origin, direction, spread, behind);
#endif
    return behind;
}

vec3 refract_environment(vec3 color, Surface s, bool solid) {
    // Refraction: environment seen along the refracted ray, weighted by Fresnel
    // transmittance (twice, in and out, through a solid ball), blended with the surface
    // colour by alpha (alpha 0 = clear).
    float ior = v_reflect.y;
#ifdef DISPERSION
    // Each channel bent by its own index (a prism's colours): red and blue (ior - 1) x 0.025 x
    // dispersion either side of green's ior (three.js's spread of KHR_materials_dispersion),
    // each with its own ray and its own Fresnel transmittance.
    float half_spread = (ior - 1.0) * 0.025 * dispersion;
    vec3 iors = max(vec3(ior - half_spread, ior, ior + half_spread), vec3(1.0));
    vec3 transmittance, behind;
    for (int c = 0; c < 3; ++c) {
        vec3 direction = solid ? solid_sphere_exit(-s.to_eye, s.normal, iors[c])
                               : refract(-s.to_eye, s.normal, 1.0 / iors[c]);
        float passed = 1.0 - schlick_fresnel(s.to_eye, s.normal, vec3(f0_from_ior(iors[c]))).x;
        transmittance[c] = solid ? passed * passed : passed;
        // (its own footprint: the channels' rays spread apart)
        float lod = cube_lod(direction, probe_face_size > 0.0 ? probe_face_size : sky_face_size);
        behind[c] = refracted_light(s, refraction_origin(s, iors[c], solid), direction, lod)[c];
    }
#else
    vec3 transmittance = vec3(1.0) - schlick_fresnel(s.to_eye, s.normal, vec3(f0_from_ior(ior)));
    if (solid) transmittance *= transmittance;  // the exit's angle is the entry's
    vec3 behind = refracted_light(s, refraction_origin(s, ior, solid), s.refract_dir, s.refract_lod);
#endif
    // The surface's own reflection of the environment lies over what it lets through, whatever
    // its alpha (Fresnel: 1 - F passes, F is reflected).
    vec3 transmitted = transmittance * s.albedo * behind + environment_light;
#ifdef SCREEN_REFLECTION
    reflect_weight = mix(environment_reflect_weight, reflect_weight, s.alpha);
    reflect_added = mix(environment_reflect_added, reflect_added, s.alpha);
#endif
    return mix(transmitted, color, s.alpha);
}

vec3 apply_refract(uint variant, vec3 color, Surface s) {
    switch (variant) {
        case REFRACT_ENVIRONMENT: return refract_environment(color, s, false);
        case REFRACT_SOLID: return refract_environment(color, s, true);
        default: return color;
    }
}

// --- Emissive slot --------------------------------------------------------------------
vec3 apply_emissive(uint variant, vec3 color, Surface s) {
    switch (variant) {
        case EMISSIVE_EMISSIVE: return color + v_surface.z * emitted_colour(s);  // power x diffuse (or emissive map)
        default: return color;
    }
}

#ifdef CHECKER
// A generated checker drawn from its cells (engine.render.renderer.checker_look): the share
// of the pixel's footprint on odd cells, box-filtered in closed form (the integral of the
// cells' square wave over the footprint fwidth(p) wide, as in Inigo Quilez's filtered
// checkerboard), so edges are sharp up close and the board averages to grey far off.
uniform float checker_cells;  // cells across the UV square
uniform vec3 checker_even;    // linear colour of cells whose integer coordinates sum even
uniform vec3 checker_odd;

vec3 checker_colour(vec2 uv) {
    vec2 p = uv * checker_cells;
    vec2 w = 1.25 * fwidth(p) + 1e-4;  // a box a little wider than the pixel: no moire at grazing angles
    vec2 i = 2.0 * (abs(fract((p - 0.5 * w) * 0.5) - 0.5) - abs(fract((p + 0.5 * w) * 0.5) - 0.5)) / w;
    float odd = 0.5 - 0.5 * i.x * i.y;
    // Where a cell is under a pixel or two, what is left of the pattern beats with the
    // pixel grid: fade it to the board's mean, as a texture's smallest mips do.
    odd = mix(odd, 0.5, smoothstep(0.75, 1.5, max(w.x, w.y)));
    return mix(checker_even, checker_odd, odd);
}
#endif

void main() {
#ifdef MASKED
    // (the level's own size; its depth and normals pass at half of it: NODE_STEP 2)
    dropped_pixel = texelFetch(node_map, ivec2(gl_FragCoord.xy) * NODE_STEP, 0).r != node_index;
#endif
#ifdef SCREEN_REFLECTION
    // Nothing reflected, for the early returns (an unlit mirror: its composite paints it).
    out_reflect_weight = vec4(0.0);
    out_reflect_added = vec4(0.0);
    out_reflect_normal = vec4(0.0);
#endif
#ifdef UNLIT_SURFACE
    // A mirror the view tree's composites paint over at weight 1 (unlit_mirrors.shading_replaced):
    // its colour is never seen, so only its depth and ids count (the claims below read them).
    out_color = vec4(0.0, 0.0, 0.0, 1.0);
    out_surface = v_slots.w;
    out_seen = SEEN(v_slots.w, length(v_world_pos - ray_eye(VIEW_POINT, VIEW_AXIS, v_world_pos)) * VIEW_WAY_SCALE);
    out_node = node_index;
    DISCARD_DROPPED();
    return;
#endif
#ifdef TRIVIAL
    DISCARD_DROPPED();
    out_color = vec4(1000.0, 0.0, 1000.0, 1.0); out_surface = v_slots.w; out_seen = uvec4(v_slots.w, 0u, 0u, 0u); out_node = node_index; return;
#endif
    view_eye = ray_eye(VIEW_POINT, VIEW_AXIS, v_world_pos);
    Surface s;
    s.position = v_world_pos;
    s.to_eye = normalize(VIEW_EYE - v_world_pos);
    s.normal = normalize(v_normal);
    if (!gl_FrontFacing) s.normal = -s.normal;
    s.geometric_normal = s.normal;
#ifdef SUBSURFACE
    subsurface_begin(s.geometric_normal, v_world_pos);  // (the curvature: derivatives, before any branch)
#endif
#ifdef PARALLAX
    parallax_shift = parallax_offset(s.geometric_normal, v_world_pos, s.to_eye, MAP_UV_PLAIN(UV_BIT_NORMAL_MAP));
#endif
#ifdef NORMAL_MAP
    s.normal = mapped_normal(s.normal, v_world_pos, MAP_UV_PLAIN(UV_BIT_NORMAL_MAP), v_surface.w);
#endif
    vec4 base = v_color;
#ifdef CHECKER
    base.rgb *= checker_colour(MAP_UV(UV_BIT_TEXTURE));
#else
    if (has_albedo_map) base *= MAP_TEXTURE(albedo_map, UV_BIT_TEXTURE);
#endif
#ifdef VERTEX_COLOR
    base *= v_vertex_color;
#endif
#ifdef ALPHA_CUTOFF
    // A cutout (Material.alpha_cutoff): nothing where the alpha falls below it; the shadow
    // maps leave the same texels out (shadow.frag).
    dropped_pixel = dropped_pixel || base.a < alpha_cutoff;
#endif
#ifdef DEPTH_NORMALS
    // The depth and normals pass of screen-space ambient occlusion (engine/render/screen_occlusion.py;
    // shaders/include/occlusion_geometry.glsl): the surface's own normal (a normal map's bumps
    // would find occluders in flat ground) in the view's space, and one over the distance along
    // its axis (1 / clip w: any view's, whatever its near plane).
    out_color = vec4(normalize(mat3(camera.view) * s.geometric_normal), gl_FragCoord.w);
    DISCARD_DROPPED();
    return;
#endif
    s.albedo = base.rgb;
    s.alpha = base.a;
#ifdef FOAM
    // A water's shore foam, drawn over its view's level (foam.glsl): its own colour, covering
    // as much of the surface as the shore and the pattern leave; none, nothing drawn.
    int foam_k = foam_slot(v_slots.w);
    s.albedo = foam_k >= 0 ? foam_colour[foam_k].rgb : vec3(0.0);
    s.alpha = foam_k >= 0 ? foam_cover(foam_k, v_world_pos, gl_FragCoord.xy) : 0.0;
#ifdef DISCARDS_LAST
    dropped_pixel = dropped_pixel || s.alpha <= 0.0;
#else
    if (s.alpha <= 0.0) discard;
#endif
#endif
    // A decal's cut (the transparent slot's code 3) with no alpha left shows nothing: it writes
    // nothing either (its id would take a click through a clear part of its image, its
    // corners).  (Water and see-through surfaces keep their ids at any alpha: the view tree
    // claims their pixels by them.)  A GPU's builds (DISCARDS_LAST: Gpu.discards_last) drop
    // it with the other left-out pixels, after the derivatives the rest of its quad takes; a
    // software rasteriser's builds discard it here, unshaded: llvmpipe keeps every pixel of a quad
    // running, so its derivatives stay defined, and there every frame drew 5% slower with
    // the test last (measured, issue 40).
#ifdef DISCARDS_LAST
    dropped_pixel = dropped_pixel || (transparent == 3 && s.alpha < 0.5 / 255.0);
#else
    if (transparent == 3 && s.alpha < 0.5 / 255.0) discard;
#endif
    s.metallic = v_surface.x;
    s.roughness = v_surface.y;
#ifdef FOAM
    s.metallic = 0.0;   // (foam scatters: white water is rough and no metal)
    s.roughness = 1.0;
#endif
    float metal_share = apply_metallic_roughness(s);  // x the metallic-roughness map
    s.highlight_roughness = filtered_roughness(s.roughness, s.normal);
#ifdef ANISOTROPY
    anisotropic_frame(s.normal, v_world_pos, MAP_UV_PLAIN(UV_BIT_NORMAL_MAP), anisotropy.y, s.highlight_roughness * s.highlight_roughness);
#endif
#ifdef CLEARCOAT
    coat_normal = s.geometric_normal;
    coat_roughness = filtered_roughness(clearcoat.y, coat_normal);
#endif
    s.occlusion = material_occlusion();
    s.direct_occlusion = 1.0;
    s.sun_contact = 1.0;
#ifdef SCREEN_OCCLUSION
    vec3 screen_shares = screen_occlusion_shares();
    s.occlusion *= screen_shares.r;
    s.direct_occlusion = screen_shares.g;
    s.sun_contact = screen_shares.b;
#endif
    s.f0 = mix(dielectric_f0, s.albedo, s.metallic);
#ifdef IRIDESCENCE
    s.f0 = iridescent_f0(s.f0, max(dot(s.normal, s.to_eye), 1e-4));
#endif
    s.reflect_dir = reflect(-s.to_eye, s.normal);
#ifdef ANISOTROPY
    s.reflect_dir = anisotropic_reflect_dir(s.normal, s.to_eye, s.roughness);
#endif
    s.refract_dir = refract(-s.to_eye, s.normal, 1.0 / max(v_reflect.y, 1.0));
    if (SLOT_REFRACT == REFRACT_SOLID) s.refract_dir = solid_sphere_exit(-s.to_eye, s.normal, max(v_reflect.y, 1.0));
    // The sky LODs only where a slot samples the sky: about a sixth of a frame's shading on
    // llvmpipe otherwise. The variants are flat per instance, so every pixel of a 2 x 2 quad
    // (one primitive) takes the same branch and the derivatives stay defined.
    s.reflect_lod = 0.0;
    s.environment_weight = vec3(0.0);
    vec2 split_sum = environment_brdf(s.roughness, max(dot(s.normal, s.to_eye), 0.0));
    s.energy_compensation = energy_compensation(s.f0, split_sum);
    if (environment_reflected()) {
        float share = SLOT_REFLECT == REFLECT_NONE ? v_reflect.x : 1.0;
        s.environment_weight = environment_share(s.f0, split_sum) * (share * float(lights.counts.w));
        s.reflect_lod = cube_lod(s.reflect_dir, sky_face_size);
    }
    if (SLOT_REFLECT == REFLECT_SKYBOX) s.reflect_lod = cube_lod(s.reflect_dir, sky_face_size);
    if (SLOT_REFLECT == REFLECT_CUBE) s.reflect_lod = cube_lod(s.reflect_dir, probe_face_size);
    s.refract_lod = 0.0;
    if (SLOT_REFRACT == REFRACT_ENVIRONMENT || SLOT_REFRACT == REFRACT_SOLID)
        s.refract_lod = cube_lod(s.refract_dir, probe_face_size > 0.0 ? probe_face_size : sky_face_size);

    AmbientBoxes boxes = ambient_boxes(s.position, s.geometric_normal);
#ifdef UNLIT_MATERIAL
    vec3 lit = s.albedo;  // Material.unlit: its colour as it is, no light, shadow or reflection on it
#else
    vec3 lit = direct_lighting(s, boxes);
#ifdef SHEEN
    // The sheen over the material (glTF's layering): the material keeps 1 - max(sheen) x E(n.v)
    // of its light, the sheen's light and reflection lie on top (a see-through material keeps
    // them whole, as its highlights and reflections: highlight_light, environment_light).
    float sheen_albedo = environment_brdf_rows(sheen.a, max(dot(s.normal, s.to_eye), 0.0)).b;
    float sheen_loss = 1.0 - max(max(sheen.r, sheen.g), sheen.b) * sheen_albedo;
    vec3 sheen_direct = sheen.rgb * sheen_light;
    vec3 sheen_ambient = sheen.rgb * sheen_environment(s, boxes, sheen_albedo);
    lit = lit * sheen_loss + sheen_direct * s.direct_occlusion + sheen_ambient;
    highlight_light = highlight_light * sheen_loss + sheen_direct;
    environment_light = environment_light * sheen_loss + sheen_ambient;
#ifdef SCREEN_REFLECTION
    reflect_weight *= sheen_loss;  // the reflections under the sheen, scaled as its light is
    reflect_added *= sheen_loss;
#endif
#endif
#endif
#if defined(SCREEN_REFLECTION) && defined(METALLIC_ROUGHNESS_MAP)
    vec3 lit_weight = reflect_weight, lit_added = reflect_added;  // (the environment reflection's, in lit)
#endif
    kept_light = highlight_light * s.direct_occlusion + environment_light;
    vec3 lit_kept = kept_light;
    vec3 color = mapped_reflection(SLOT_REFLECT, lit, apply_reflect(SLOT_REFLECT, lit, s), metal_share);
    kept_light = mapped_reflection(SLOT_REFLECT, lit_kept, kept_light, metal_share);
    color = apply_refract(SLOT_REFRACT, color, s);
    vec3 emitted = apply_emissive(SLOT_EMISSIVE, vec3(0.0), s);
    color += emitted;
#ifdef CLEARCOAT
    // The coat over it all: the material, its emission too, keeps what the coat's Fresnel
    // reflection leaves; the coat's highlights and reflection lie on top (and a see-through
    // material keeps them whole, as it does its reflections: kept_light).
    float coat_nv = max(dot(coat_normal, s.to_eye), 0.0);
    float coat_loss = 1.0 - clearcoat.x * schlick_fresnel(s.to_eye, coat_normal, vec3(0.04)).x;
    vec3 coat = clearcoat.x * (coat_light + coat_environment(s, boxes, coat_nv));
    color = color * coat_loss + coat;
    kept_light = kept_light * coat_loss + coat;
    emitted *= coat_loss;
#ifdef SCREEN_REFLECTION
    reflect_weight *= coat_loss;  // the reflections under the coat, scaled as the colour is
    reflect_added *= coat_loss;   // (the coat's own is the sky's or probes', not the screen's)
#endif
#endif
#ifdef SCREEN_REFLECTION
    // The reflections through what follows the reflect slot: the map's metal share
    // (mapped_reflection mixes lit and the slot's by it), the fog's transmittance (fogged
    // mixes by it); a refraction mixed them by the surface's alpha (refract_environment);
    // emission adds and leaves them as they are.
#ifdef METALLIC_ROUGHNESS_MAP
    if (SLOT_REFLECT == REFLECT_SKYBOX || SLOT_REFLECT == REFLECT_CUBE) {
        reflect_weight = mix(lit_weight, reflect_weight, metal_share);
        reflect_added = mix(lit_added, reflect_added, metal_share);
    }
#endif
    vec3 kept = vec3(1.0);
#ifdef FOG
    kept *= exp(-fog_depth(fog_start(VIEW_EYE, VIEW_ENTRY, v_world_pos), v_world_pos));
#endif
    out_reflect_weight = vec4(reflect_weight * kept, s.roughness);
    out_reflect_added = vec4(hdr_store(reflect_added * kept), float(v_slots.w & 2047u));
    out_reflect_normal = vec4(s.normal, float((v_slots.w >> 11u) & 2047u));
#endif
    float alpha = 1.0;
#ifdef FOAM
    color *= s.alpha;   // (premultiplied whole: foam has no light of its own over what shows through)
    alpha = s.alpha;
#else
    if (transparent != 0) {
        // Premultiplied by the alpha (the transparent slot blends ONE, ONE_MINUS_SRC_ALPHA):
        // all of the colour (fade), or all but its reflected and emitted light (kept_light:
        // highlights, the environment's and a slot's reflection; emission, as Unity's Standard
        // shader adds it after its premultiply), whole over what shows through
        // (Material.blend "transparent").
        vec3 kept = transparent == 2 ? kept_light + emitted : vec3(0.0);
        color = (color - kept) * s.alpha + kept;
        alpha = s.alpha;
    }
#endif
#ifdef FOG
    // The air between where this view's rays enter it (its eye, or the surface it looks out
    // of) and the point; a composite fogs the stretch before (fog.glsl).  fog_view is the
    // colour x the transmittance plus the fog's own light: of that light a see-through
    // surface gives its alpha's share (what shows through was fogged on its own way).
    vec3 fogged_color = fog_view(color, VIEW_EYE, VIEW_ENTRY, v_world_pos);
#ifdef FOAM
    fogged_color -= (1.0 - alpha) * fog_view(vec3(0.0), VIEW_EYE, VIEW_ENTRY, v_world_pos);
#else
    if (transparent != 0) fogged_color -= (1.0 - alpha) * fog_view(vec3(0.0), VIEW_EYE, VIEW_ENTRY, v_world_pos);
#endif
    color = fogged_color;
#endif
    out_color = vec4(hdr_store(color), alpha);
    out_surface = v_slots.w;
    out_seen = SEEN(v_slots.w, length(v_world_pos - VIEW_EYE) * VIEW_WAY_SCALE);
    out_node = node_index;
    DISCARD_DROPPED();
}
