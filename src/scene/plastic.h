// The coating of the plastic material (MaterialKind::Plastic), with Mitsuba 3's semantics for
// `roughplastic` (rough coating) and `plastic` (smooth coating). A dielectric interface of
// relative index eta over a Lambertian base of albedo kd; with co = n . wo (viewer side) and
// ci = n . wi (light side), f cos(theta_i) is
//   specular: ks F(wo . h, eta) D(h) G1(wo) G1(wi) / (4 co)       (rough: GGX alpha, h = half vector)
//             a delta reflection of weight ks F(co, eta)          (smooth)
//   diffuse:  kd / (1 - R) T(co) T(ci) ci / (pi eta^2)             (nonlinear: kd / (1 - kd R))
// T(c) is the coating's transmittance for light arriving at cosine c: rough, the fraction of
// it the GGX interface refracts into the base and that leaves the microsurface unshadowed
// (the integral over visible normals m of (1 - F(wo . m)) G1(refracted direction)); smooth,
// 1 - F(c). R is the coating's reflectance for light leaving the base, cosine weighted: rough,
// 2 times the mean over 64 evenly spaced cosines mu of mu times the GGX interface's reflected
// albedo (integral over visible normals of F(wo . m, 1 / eta) G1(reflected direction));
// smooth, the diffuse Fresnel reflectance of 1 / eta (the fits of Egan and Hilgeman 1973 and of
// d'Eon and Irving 2011). The rough T is a table of 64 cosines, linearly interpolated; T and R
// come with their derivatives in alpha and eta (central differences of the quadrature) so that
// both parameters stay differentiable.
#pragma once
#include <algorithm>
#include <memory>

namespace edgepath {

constexpr int kCoatResolution = 64;
// How far from 1 a coating's relative index must be (Mitsuba refuses equal indices).
constexpr float kMinCoatIndexContrast = 1e-3f;

struct CoatTable {
    bool smooth = false;
    float alpha = 0.f, eta = 1.5f;
    // Rough only: T at cosine i / (kCoatResolution - 1) and its derivatives.
    float t[kCoatResolution] = {}, dt_dalpha[kCoatResolution] = {}, dt_deta[kCoatResolution] = {};
    float r = 0.f, dr_dalpha = 0.f, dr_deta = 0.f;  // R and its derivatives
};

// The coating of GGX alpha `alpha` (ignored when smooth) and relative index eta (> 0, != 1).
CoatTable make_coat_table(float alpha, float eta, bool smooth);
// The same, shared with the scenes built recently for the same coating.
std::shared_ptr<const CoatTable> coat_table(float alpha, float eta, bool smooth);

// The diffuse Fresnel reflectance of an interface of relative index eta (unpolarised, cosine
// weighted), and its derivative.
double fresnel_diffuse_reflectance(double eta, double* d_eta = nullptr);

namespace detail {
// The rough table's value at cosine c (0..1) and its slope in c: linear interpolation, the
// index of the segment and its weight.
struct CoatLookup {
    int i;
    float w;
};
inline CoatLookup coat_lookup(float c) {
    const float x = std::clamp(c, 0.f, 1.f) * float(kCoatResolution - 1);
    const int i = std::min(int(x), kCoatResolution - 2);
    return {i, x - float(i)};
}
}  // namespace detail

}  // namespace edgepath
