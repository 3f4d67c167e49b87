// ColorGrading (components/post.py) as the present draws it and a picture panel over the
// frame draws it again (screen_text.frag): with GRADE, grade() on the exposed linear colour
// before the tone curve; with LUT, lut_graded() on the encoded colour after it.  The
// uniforms are written by engine/render/grading.py (grade_uniforms, lut_lookup).
#ifdef GRADE
uniform mat3 white_balance;   // linear sRGB, adapted (engine/render/grading.py)
uniform float contrast;       // about middle grey, in log space
uniform vec3 slope;           // the ASC Color Decision List's
uniform vec3 offset;
uniform vec3 power;
uniform float saturation;     // about Rec. 709 luma

// ColorGrading's order: white balance, contrast, slope-offset-power, saturation.  Each step
// keeps values >= 0 (pow of a negative number is undefined in GLSL).
vec3 grade(vec3 c) {
    c = max(white_balance * c, 0.0);
    c = 0.18 * pow(max(c, 1e-10) / 0.18, vec3(contrast));
    c = pow(max(c * slope + offset, 0.0), power);
    float luma = dot(c, vec3(0.2126, 0.7152, 0.0722));
    return max(luma + saturation * (c - luma), 0.0);
}
#endif
#ifdef LUT
uniform sampler3D lut_map;    // ColorGrading.lut (engine/assets/color_lut.py), trilinear
uniform vec3 lut_scale;       // encoded colour -> its texture coordinates (grading.lut_lookup)
uniform vec3 lut_bias;
uniform float lut_strength;

// The encoded colour looked up in the grade's table, by its strength.
vec3 lut_graded(vec3 srgb) {
    return mix(srgb, textureLod(lut_map, srgb * lut_scale + lut_bias, 0.0).rgb, lut_strength);
}
#endif
