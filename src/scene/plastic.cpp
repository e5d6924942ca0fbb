// The plastic coating's tables (scene/plastic.h): the GGX interface's albedos by
// Gauss-Legendre quadrature over the visible normals of the incident direction, in double.
#include "scene/plastic.h"

#include <cmath>
#include <deque>
#include <memory>
#include <mutex>
#include <vector>

#include <tbb/parallel_for.h>

#include "scene/bsdf_diff.h"

namespace edgepath {
namespace {

using V3 = TVec3<double>;

// Gauss-Legendre nodes and weights on [0, 1] (Newton's iteration on the Legendre polynomial).
struct Quadrature {
    std::vector<double> x, w;
    std::vector<double> r, cos_phi, sin_phi;  // sqrt(x), cos and sin of 2 pi x
};
Quadrature gauss_legendre(int n) {
    Quadrature q;
    q.x.resize(size_t(n));
    q.w.resize(size_t(n));
    for (int i = 0; i < n; ++i) {
        double z = std::cos(detail::pi<double>() * (i + 0.75) / (n + 0.5));
        double dp = 1;
        for (int it = 0; it < 100; ++it) {
            double p0 = 1, p1 = 0;
            for (int k = 1; k <= n; ++k) {
                const double p2 = p1;
                p1 = p0;
                p0 = ((2 * k - 1) * z * p1 - (k - 1) * p2) / k;
            }
            dp = n * (z * p0 - p1) / (z * z - 1);
            const double step = p0 / dp;
            z -= step;
            if (std::abs(step) < 1e-15) break;
        }
        q.x[size_t(i)] = 0.5 * (z + 1);
        q.w[size_t(i)] = 1 / ((1 - z * z) * dp * dp);  // (2 / ((1 - z^2) P'^2)) / 2 on [0, 1]
    }
    for (double x : q.x) {
        q.r.push_back(std::sqrt(x));
        q.cos_phi.push_back(std::cos(2 * detail::pi<double>() * x));
        q.sin_phi.push_back(std::sin(2 * detail::pi<double>() * x));
    }
    return q;
}

// The GGX visible normal of wo (upper hemisphere) for the sample (u1, u2) (Heitz 2018), given
// r = sqrt(u1) and the cosine and sine of 2 pi u2.
V3 visible_normal(const V3& wo, double a, double r, double cos_phi, double sin_phi) {
    const V3 vh = normalize(V3(a * wo.x, a * wo.y, wo.z));
    const double lensq = vh.x * vh.x + vh.y * vh.y;
    const V3 t1 = lensq > 0 ? V3(-vh.y, vh.x, 0) / std::sqrt(lensq) : V3(1, 0, 0);
    const V3 t2 = cross(vh, t1);
    const double p1 = r * cos_phi, s = 0.5 * (1 + vh.z);
    const double p2 = (1 - s) * std::sqrt(std::max(0.0, 1 - p1 * p1)) + s * r * sin_phi;
    const V3 nh = t1 * p1 + t2 * p2 + vh * std::sqrt(std::max(0.0, 1 - p1 * p1 - p2 * p2));
    return normalize(V3(a * nh.x, a * nh.y, std::max(1e-7, nh.z)));
}

// Smith's G1 for a direction at cosine c to the macro normal (either side), any microfacet
// normal it sees.
double g1(double c, double a) {
    const double c2 = c * c;
    if (c2 >= 1) return 1;
    return 2 / (1 + std::sqrt(1 + a * a * (1 - c2) / c2));
}

// For light arriving at cosine mu on the interface of relative index e, the fraction the GGX
// surface reflects (reflect) or transmits, each leaving the microsurface unshadowed.
double albedo(double mu, double a, double e, bool reflect, const Quadrature& q) {
    const V3 wo(std::sqrt(std::max(0.0, 1 - mu * mu)), 0, mu);
    double sum = 0;
    for (size_t i = 0; i < q.x.size(); ++i)
        for (size_t j = 0; j < q.x.size(); ++j) {
            const V3 m = visible_normal(wo, a, q.r[j], q.cos_phi[i], q.sin_phi[i]);
            const double om = dot(wo, m);
            if (!(om > 0)) continue;
            const double F = detail::fresnel_dielectric(om, e);
            double v;
            if (reflect) {
                const V3 wi = m * (2 * om) - wo;
                v = wi.z > 0 ? F * g1(wi.z, a) : 0;
            } else {
                const double sin2 = (1 - om * om) / (e * e);
                if (sin2 >= 1) continue;
                const V3 wt = m * (om / e - std::sqrt(1 - sin2)) - wo / e;
                v = wt.z < 0 ? (1 - F) * g1(wt.z, a) : 0;
            }
            sum += v * q.w[i] * q.w[j];
        }
    return sum;
}

// Mitsuba's node counts: 32 per axis for e > 1, 128 for e < 1 (total internal reflection
// makes the integrand steep).
const Quadrature& quadrature(double e) {
    static const Quadrature coarse = gauss_legendre(32), fine = gauss_legendre(128);
    return e > 1 ? coarse : fine;
}

double mu_at(int i) { return std::max(1e-6, double(i) / (kCoatResolution - 1)); }

// R: 2 mean(mu albedo_reflected(mu, 1 / eta)) over the table's cosines (in parallel, summed in
// order).
double internal_reflectance(double a, double eta) {
    const Quadrature& q = quadrature(1 / eta);
    double terms[kCoatResolution];
    tbb::parallel_for(0, kCoatResolution, [&](int i) { terms[i] = mu_at(i) * albedo(mu_at(i), a, 1 / eta, true, q); });
    double sum = 0;
    for (double t : terms) sum += t;
    return 2 * sum / kCoatResolution;
}

}  // namespace

double fresnel_diffuse_reflectance(double eta, double* d_eta) {
    if (eta < 1) {
        // Egan and Hilgeman (1973): -1.4399 eta^2 + 0.7099 eta + 0.6681 + 0.0636 / eta
        if (d_eta) *d_eta = -2 * 1.4399 * eta + 0.7099 - 0.0636 / (eta * eta);
        return -1.4399 * eta * eta + 0.7099 * eta + 0.6681 + 0.0636 / eta;
    }
    // d'Eon and Irving (2011): a quintic in x = 1 / eta
    const double c[6] = {0.919317, -3.4793, 6.75335, -7.80989, 4.98554, -1.36881};
    const double x = 1 / eta;
    double v = 0, dv = 0;
    for (int k = 5; k >= 0; --k) {
        dv = dv * x + v;
        v = v * x + c[k];
    }
    if (d_eta) *d_eta = dv * -x * x;
    return v;
}

std::shared_ptr<const CoatTable> coat_table(float alpha, float eta, bool smooth) {
    // The tables of the last few coatings: a scene rendered again, or its gradient pass, finds
    // its own (building one takes a few hundred million floating-point operations).
    static std::mutex mutex;
    static std::deque<std::shared_ptr<const CoatTable>> recent;
    {
        std::lock_guard<std::mutex> lock(mutex);
        for (const auto& t : recent)
            if (t->smooth == smooth && t->eta == eta && (smooth || t->alpha == alpha)) return t;
    }
    auto t = std::make_shared<const CoatTable>(make_coat_table(alpha, eta, smooth));
    std::lock_guard<std::mutex> lock(mutex);
    recent.push_front(t);
    if (recent.size() > 16) recent.pop_back();
    return t;
}

CoatTable make_coat_table(float alpha, float eta, bool smooth) {
    CoatTable t;
    t.smooth = smooth;
    t.alpha = alpha;
    t.eta = eta;
    if (smooth) {
        // R = Fdr(1 / eta)
        double d = 0;
        t.r = float(fresnel_diffuse_reflectance(1.0 / eta, &d));
        t.dr_deta = float(d * -1.0 / (double(eta) * eta));
        return t;
    }
    const double a = alpha, e = eta;
    // Central differences of the quadratures, over steps of 1% of alpha and eta. The integrands
    // have a kink where total internal reflection sets in (R's, and T's for eta < 1), whose
    // place moves across the fixed nodes as alpha and eta change: the quadratures' values
    // wiggle about their smooth trend by some 1e-5, and steps of 1e-4 (as before) took those
    // wiggles for the slope: at alpha 0.2, eta 1.5, dR/deta came out 0.594 against the trend's
    // 0.604 (steps of 0.003 to 0.03 agree on it), dR/dalpha -0.692 against -0.707, and the
    // diffuse lobe's derivative in eta 4% off the finite difference of renders. At 1% the
    // central difference's own error (of the order of the step squared) is below 1e-4.
    const double ha = 1e-2 * std::max(a, 0.01), he = 1e-2 * e;
    const Quadrature& q = quadrature(e);
    tbb::parallel_for(0, kCoatResolution, [&](int i) {
        const double mu = mu_at(i);
        t.t[i] = float(albedo(mu, a, e, false, q));
        t.dt_dalpha[i] = float((albedo(mu, a + ha, e, false, q) - albedo(mu, a - ha, e, false, q)) / (2 * ha));
        t.dt_deta[i] = float((albedo(mu, a, e + he, false, quadrature(e + he)) -
                              albedo(mu, a, e - he, false, quadrature(e - he))) / (2 * he));
    });
    t.r = float(internal_reflectance(a, e));
    t.dr_dalpha = float((internal_reflectance(a + ha, e) - internal_reflectance(a - ha, e)) / (2 * ha));
    t.dr_deta = float((internal_reflectance(a, e + he) - internal_reflectance(a, e - he)) / (2 * he));
    return t;
}

}  // namespace edgepath
