// shade_vertex (render/path.h) for the plain case, a vector of paths at a time: the standard
// material (MaterialKind::Standard): the Lambertian lobe, and the GGX lobe where the specular
// is not black, its reflectances and roughness constant or textured. PathBatch
// (render/batch.cpp) gathers such vertices into the arrays of ShadeLanes (one entry a path:
// structure of arrays), with the random numbers and what needs a table or a branch per path
// computed beforehand path by path: the reflectances, alpha and the GGX lobe's probability,
// the light picked and, for a triangle sampled by area with a constant emission and no spot,
// its vertices (any other light's sample is taken there by Scene::sample_area_light and
// handed over whole), the BSDF sample's numbers, the environment's sample. Then shade_lanes
// does the arithmetic over all of them in vectors: the lobe's choice, the disk point or the
// GGX visible normal (the cosine and sine of either's angle per path, the rest in vectors),
// the bent shading normal, the frame, the BSDF sample, its ray, the light sample's point, both
// light samples' values (bsdf_eval), MIS weights (bsdf_pdf) and shadow rays; the GGX terms only
// in a vector where some path has the lobe. (The point lights are left to the gathering code,
// path by path.) Every lane performs scalar shade_vertex's floating-point operations in its
// order (render/shade_kernel.h; the scalar code's early returns, std::max and std::clamp as
// selects with the same NaN semantics), so the samples are the same bit for bit
// (Render.BatchedPlainPathsMatchTracePath, Render.BatchedGlossyPathsMatchTracePath).
//
// The plastic (MaterialKind::Plastic, rough or smooth coating: scene/plastic.h) has lanes of
// its own (shade_plastic_lanes, the same kernel with its lobes): gathered likewise with its
// index, coating table, R, the means of its reflectances and its masks (rough, smooth table,
// the coating's GGX term, nonlinear). The table's T(c) is looked up path by path with the
// scalar function itself (detail::coat_transmittance, in render/shade_lanes.cpp; in vectors,
// 1 - F(c), where all of a vector's coatings are smooth): T(co) and the coating's probability
// (plastic_coat_probability) before the sample's angle, which depends on the lobe chosen, then
// T(ci) for the sample and each light sample. The rest is in vectors: the GGX visible normal
// where rough, the smooth coating's mirror direction and weight ks F(co) / ps (next_delta: the
// continuation is a delta lobe's), the cosine-weighted base, plastic_terms' value (the base's
// kd / (1 - R) or kd / (1 - kd R) and the coating's GGX term with the dielectric's Fresnel
// reflectance), bsdf_pdf's density and the MIS weights (Render.ShadePlasticLanesWidthsAgree,
// Render.BatchedPlasticPathsMatchTracePath). The material is not a delta one: its vertices
// sample the lights whichever lobe the continuation took, as shade_vertex's do. The mirror
// (MaterialKind::Conductor) has lanes of its own as well (shade_mirror_lanes): its bent normal,
// frame, delta_scatter's direction and weight and its ray; no light samples (a delta material).
//
// The vectors are eight floats (AVX2, render/shade_lanes_avx2.cpp) on a processor that has
// AVX2 and four (SSE2, math/simd4.h) otherwise, chosen at run time: the same samples bit for
// bit either way (Render.ShadeLanesWidthsAgree), since each lane's operations are the same.
#pragma once
#include <cstddef>
#include <cstdint>
#include <cstring>

namespace edgepath {

struct CoatTable;

template <int N>
struct ShadeLanes {
    static_assert(N % 16 == 0, "whole vectors of every width");
    // In: the vertex (p, its error bound, the geometric and the shading normal), the direction
    // of the ray that found it, the path's throughput, the diffuse reflectance; masks (all bits
    // set: true) of a two-sided material and of a reflectance with luminance above 0.
    alignas(64) float p[3][N], p_error[3][N], ng[3][N], ns[3][N], dir[3][N], beta[3][N], diffuse[3][N];
    alignas(64) float two_sided[N], reflects[N];
    // The mask of a GGX lobe (a specular that is not black); where it is set, the probability
    // of sampling the lobe (specular_lobe_probability), its specular and alpha
    // (Scene::bsdf_params') and the number that chooses it (the GGX lobe where below lobe_p).
    // Elsewhere these are not written (what is there is never used: the probability is 0).
    alignas(64) float has_specular[N], lobe_p[N], specular[3][N], alpha[N], u_lobe[N];
    // The BSDF sample's two numbers for its direction: the cosine-weighted sample's point on
    // the unit disk (square_to_disk) or the GGX visible normal's (their angle's cosine and sine
    // per path, the rest in vectors).
    alignas(64) float disk[2][N];
    // The area light's sample (mask light_on): the barycentrics on the triangle picked, its
    // vertices, unit normal and largest edge component, the probability of its pick and its
    // area, its emission (constant) and whether it emits on both sides.
    alignas(64) float light_on[N], b1[N], b2[N], v0[3][N], v1[3][N], v2[3][N], light_ng[3][N], edge[N];
    alignas(64) float pmf[N], area[N], emission[3][N], two_sided_emission[N];
    // Or (mask light_given) a light sample taken by Scene::sample_area_light: its direction,
    // density, radiance, and its point with the point's error bound and normal.
    alignas(64) float light_given[N], given_dir[3][N], given_pdf[N], given_radiance[3][N];
    alignas(64) float given_p[3][N], given_p_error[3][N], given_ng[3][N];
    // The environment's sample (mask env_on): its direction, value and density.
    alignas(64) float env_on[N], env_dir[3][N], env_radiance[3][N], env_pdf[N];
    // The plastic's lanes (shade_plastic_lanes; MaterialKind::Plastic, Scene::bsdf_params'
    // values): its relative index, the coating's R (CoatTable::r), the means of the specular
    // and of the diffuse reflectance (plastic_coat_probability's ks and kd); masks of a rough
    // coating (a roughness above 0), of a smooth table (T(c) = 1 - F(c), computed in vectors
    // where every lane of a vector has one), of the rough coating's lobe in the value (the table
    // not smooth, the specular not black) and of `nonlinear`; the coating's table. Their
    // specular, alpha and lobe number are in specular, alpha and u_lobe above (has_specular,
    // lobe_p not read).
    alignas(64) float eta[N], coat_r[N], ks[N], kd[N], rough[N], coat_smooth[N], coat_lobe[N], nonlinear[N];
    // Out: the mask of a continuation along the smooth coating's mirror direction (a delta
    // lobe: next_pdf is its probability, next_beta its weight).
    alignas(64) float next_delta[N];
    const CoatTable* coat[N];

    // Out: the bent shading normal (into ns); the continuation (mask goes_on), its ray and
    // throughput past it and the BSDF sample's density; the area light's shadow ray (mask
    // light_on), what it adds if nothing hides it; the environment's likewise (mask env_on, its
    // direction env_dir, its tmax infinite).
    alignas(64) float goes_on[N], next_origin[3][N], next_dir[3][N], next_beta[3][N], next_pdf[N];
    alignas(64) float light_origin[3][N], light_dir[3][N], light_tmax[N], light_value[3][N];
    alignas(64) float env_origin[3][N], env_value[3][N];
    // Out, for the paths the gradient pass records (PathVertexRecord's NeeRecord): each light
    // sample's MIS weight over its density (shade_vertex's `scale`); the area light's sample's
    // unit direction and distance (LightSample's dir and dist; written where light_on was set
    // on the way in, read where the sample was taken in the vectors).
    alignas(64) float light_scale[N], env_scale[N], light_to[3][N], light_dist[N];

    ShadeLanes() {
        // The lanes past the last path of a vector compute on whatever is there: zeros, then
        // earlier paths' values (never read back).
        float* all = reinterpret_cast<float*>(this);
        for (size_t i = 0; i < sizeof(*this) / sizeof(float); ++i) all[i] = 0.f;
    }
};

// A mask lane's float (all bits set: true), and whether lane k of a mask array is set.
inline float lane_mask(bool b) {
    float f;
    const uint32_t bits = b ? ~0u : 0u;
    std::memcpy(&f, &bits, sizeof f);
    return f;
}
inline bool lane_set(const float* mask, int k) {
    uint32_t bits;
    std::memcpy(&bits, mask + k, sizeof bits);
    return bits != 0;
}

// The paths of a batch (render/batch.h's kBatchSize) that shade_lanes takes.
constexpr int kShadeBatch = 64;

// The vectors' widths: SSE2's 4 floats, AVX2's 8; Auto: the widest this processor has.
enum class ShadeWidth { Auto, Sse2, Avx2 };

// Lanes [0, n) of L shaded (render/shade_kernel.h), in vectors of the width in force.
// `glossy`: whether any of them has a GGX lobe (if not, has_specular is not read: the
// Lambertian lobe alone).
void shade_lanes(ShadeLanes<kShadeBatch>& L, int n, bool mis, bool glossy);
// The same in vectors of width w (Auto: the width in force); w must be available.
void shade_lanes(ShadeLanes<kShadeBatch>& L, int n, bool mis, bool glossy, ShadeWidth w);
// Lanes [0, n) of L, every one a plastic vertex (MaterialKind::Plastic, rough or smooth
// coating), shaded likewise: shade_vertex's operations for the plastic, bit for bit.
void shade_plastic_lanes(ShadeLanes<kShadeBatch>& L, int n, bool mis);
void shade_plastic_lanes(ShadeLanes<kShadeBatch>& L, int n, bool mis, ShadeWidth w);
// Lanes [0, n) of L, every one a smooth conductor's vertex (MaterialKind::Conductor: the
// mirror), shaded likewise: its continuation only (no light samples; light_on and env_on not
// written, next_delta set where it goes on).
void shade_mirror_lanes(ShadeLanes<kShadeBatch>& L, int n);
void shade_mirror_lanes(ShadeLanes<kShadeBatch>& L, int n, ShadeWidth w);
// The scalar steps of the plastic's lanes, for the kernels (render/shade_lanes.cpp, compiled
// for the baseline processor): T(c) (detail::coat_transmittance) of lanes [k, k + count) for
// the cosines c (in place), and for lanes [k, k + count) T(co) and plastic_coat_probability's
// value of each lane's co (the arrays indexed by lane).
void plastic_coat_transmittances(const ShadeLanes<kShadeBatch>& L, int k, int count, float* c);
void plastic_coat_probabilities(const ShadeLanes<kShadeBatch>& L, int k, int count, const float* co, float* t_o,
                                float* ps);
// Whether this build and processor can run width w (Sse2 and Auto always).
bool shade_width_available(ShadeWidth w);
// The width shade_lanes uses: the widest available unless another was forced.
ShadeWidth shade_width();
// For tests and measurements: makes shade_lanes use width w (Auto: the widest available again)
// for every pass that starts afterwards, in every thread. Throws std::invalid_argument for a
// width this processor or build cannot run.
void force_shade_width(ShadeWidth w);

}  // namespace edgepath
