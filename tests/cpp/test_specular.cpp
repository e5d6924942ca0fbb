// The smooth materials (scene/specular.h): the mirror and the dielectric against the laws they
// implement (reflection, Snell's law, Fresnel at normal incidence, total internal reflection),
// the sampler in the local frame against the world-space function, and the adjoint against
// central finite differences in double precision.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "scene/bsdf.h"
#include "scene/specular.h"

namespace edgepath {
namespace {

DeltaParams<double> glass(double eta) { return DeltaParams<double>{Vec3d(1.0), eta, true, false}; }

TEST(Specular, MirrorReflectsAboutTheNormal) {
    const Vec3d n = normalize(Vec3d(0.2, 1.0, -0.1)), wo = normalize(Vec3d(0.5, 0.7, 0.3));
    Vec3d dir, w;
    DeltaParams<double> mirror{Vec3d(1.0, 0.5, 0.25), 1.0, false, false};
    ASSERT_TRUE(delta_scatter(mirror, n, wo, false, 1.0, dir, w));
    EXPECT_NEAR(dot(dir, n), dot(wo, n), 1e-12);
    EXPECT_NEAR(length(cross(dir + wo, n)), 0.0, 1e-12);  // wo + dir along n
    EXPECT_NEAR(length(dir), 1.0, 1e-12);
    // Schlick: F0 at normal incidence, 1 at grazing; here in between.
    EXPECT_GT(w.z, 0.25);
    EXPECT_LT(w.z, 1.0);
    EXPECT_DOUBLE_EQ(w.x, 1.0);
    // One-sided: nothing from behind; two-sided: the mirror image from behind.
    EXPECT_FALSE(delta_scatter(mirror, n, -wo, false, 1.0, dir, w));
    mirror.two_sided = true;
    ASSERT_TRUE(delta_scatter(mirror, n, -wo, false, 1.0, dir, w));
    EXPECT_NEAR(dot(dir, n), -dot(wo, n), 1e-12);
}

TEST(Specular, DielectricObeysSnellAndFresnel) {
    const double eta = 1.5;
    const Vec3d n(0, 0, 1);
    // Normal incidence: F = ((eta - 1) / (eta + 1))^2 from either side.
    const double f0 = (eta - 1) * (eta - 1) / ((eta + 1) * (eta + 1));
    EXPECT_NEAR(dielectric_reflectance(eta, n, Vec3d(0, 0, 1)), f0, 1e-12);
    EXPECT_NEAR(dielectric_reflectance(eta, n, Vec3d(0, 0, -1)), f0, 1e-12);
    for (double ti : {0.1, 0.6, 1.2}) {
        const Vec3d wo(std::sin(ti), 0, std::cos(ti));
        Vec3d t, w;
        ASSERT_TRUE(delta_scatter(glass(eta), n, wo, true, 1.0, t, w));
        EXPECT_NEAR(length(t), 1.0, 1e-12);
        EXPECT_LT(t.z, 0.0);
        // sin_i = eta sin_t, on the other side of the normal.
        EXPECT_NEAR(std::sin(ti), eta * (-t.x), 1e-12);
        const double F = dielectric_reflectance(eta, n, wo);
        EXPECT_NEAR(w.x, (1 - F) / (eta * eta), 1e-12);
        // Seen from inside along t, the light comes from wo, with the inverse scale.
        Vec3d back, wb;
        ASSERT_TRUE(delta_scatter(glass(eta), n, t, true, 1.0, back, wb));
        EXPECT_NEAR(length(back - wo), 0.0, 1e-12);
        EXPECT_NEAR(dielectric_reflectance(eta, n, t), F, 1e-12);  // reciprocal
        EXPECT_NEAR(wb.x, (1 - F) * eta * eta, 1e-9);
    }
    // Inside, beyond the critical angle: total internal reflection.
    const double crit = std::asin(1 / eta);
    const Vec3d inside(std::sin(crit + 0.05), 0, -std::cos(crit + 0.05));
    Vec3d t, w;
    EXPECT_EQ(dielectric_reflectance(eta, n, inside), 1.0);
    EXPECT_FALSE(delta_scatter(glass(eta), n, inside, true, 1.0, t, w));
    ASSERT_TRUE(delta_scatter(glass(eta), n, inside, false, 1.0, t, w));
    EXPECT_NEAR(t.z, inside.z, 1e-12);  // stays inside, mirrored about the normal
    EXPECT_NEAR(t.x, -inside.x, 1e-12);
}

TEST(Specular, SamplerMatchesWorldFunction) {
    BsdfParams p;
    p.kind = MaterialKind::Dielectric;
    p.eta = 1.33f;
    const Vec3f wo = normalize(Vec3f(0.3f, -0.2f, 0.8f));
    const float F = dielectric_reflectance(p.eta, Vec3f(0, 0, 1), wo);
    for (float u : {0.5f * F, 0.5f * (1.f + F)}) {
        BsdfSample s;
        ASSERT_TRUE(bsdf_sample(p, wo, u, 0.3f, 0.7f, s));
        EXPECT_TRUE(s.delta);
        EXPECT_EQ(s.refract, u >= F);
        EXPECT_NEAR(s.pdf, s.refract ? 1 - F : F, 1e-6);
        // Reflection weight F / F = 1; refraction (1 - F) / (1 - F) / eta^2.
        EXPECT_NEAR(s.weight.x, s.refract ? 1 / (p.eta * p.eta) : 1.f, 1e-5);
        EXPECT_EQ(bsdf_eval(p, wo, s.wi).x, 0.f);
        EXPECT_EQ(bsdf_pdf(p, wo, s.wi), 0.f);
    }
}

// Inputs: specular[3], eta, n[3], wo[3] (n and wo normalised inside); outputs: dir[3], weight[3].
void delta_case(bool dielectric, bool two_sided, bool refract, Vec3d n, Vec3d wo, double eta, const char* what,
                bool coat = false) {
    const double inv_prob = 1.7;
    auto unpack = [&](const std::vector<double>& x, DeltaParams<double>& p, Vec3d& N, Vec3d& O) {
        p = DeltaParams<double>{Vec3d(x[0], x[1], x[2]), x[3], dielectric, two_sided, coat};
        N = Vec3d(x[4], x[5], x[6]);
        O = Vec3d(x[7], x[8], x[9]);
    };
    n = normalize(n);
    wo = normalize(wo);
    const std::vector<double> x = {0.6, 0.4, 0.9, eta, n.x, n.y, n.z, wo.x, wo.y, wo.z};
    auto f = [&](const std::vector<double>& x) {
        DeltaParams<double> p;
        Vec3d N, O, dir(0.0), w(0.0);
        unpack(x, p, N, O);
        EXPECT_TRUE(delta_scatter(p, N, O, refract, inv_prob, dir, w)) << what;
        return std::vector<double>{dir.x, dir.y, dir.z, w.x, w.y, w.z};
    };
    std::mt19937 gen(7);
    std::normal_distribution<double> nd;
    std::vector<double> yb(6);
    for (double& v : yb) v = nd(gen);
    DeltaParams<double> p;
    Vec3d N, O;
    unpack(x, p, N, O);
    DDelta<double> d{Vec3d(0.0), Vec3d(0.0), Vec3d(0.0), 0.0};
    d_delta_scatter(p, N, O, refract, inv_prob, Vec3d(yb[0], yb[1], yb[2]), Vec3d(yb[3], yb[4], yb[5]), d);
    const std::vector<double> xb = {d.specular.x, d.specular.y, d.specular.z, d.eta, d.n.x,
                                    d.n.y,        d.n.z,        d.wo.x,       d.wo.y, d.wo.z};
    double scale = 0;
    for (double v : xb) scale = std::max(scale, std::abs(v));
    const double h = 1e-6;
    for (size_t i = 0; i < x.size(); ++i) {
        std::vector<double> xp = x, xm = x;
        xp[i] += h;
        xm[i] -= h;
        const std::vector<double> yp = f(xp), ym = f(xm);
        double fd = 0;
        for (size_t k = 0; k < 6; ++k) fd += yb[k] * (yp[k] - ym[k]) / (2 * h);
        EXPECT_NEAR(xb[i], fd, 1e-6 * (1 + scale)) << what << ": input " << i;
    }
}

TEST(Specular, Adjoint) {
    const Vec3d n(0.1, 0.2, 1.0), wo(0.4, -0.3, 0.8);
    delta_case(false, false, false, n, wo, 1.5, "mirror");
    delta_case(false, true, false, n, -wo, 1.5, "two-sided mirror from behind");
    delta_case(true, false, false, n, wo, 1.5, "glass, reflection from outside");
    delta_case(true, false, true, n, wo, 1.5, "glass, refraction from outside");
    delta_case(true, false, false, n, Vec3d(0.1, -0.1, -1.0), 1.5, "glass, reflection from inside");
    delta_case(true, false, true, n, Vec3d(0.1, -0.1, -1.0), 1.5, "glass, refraction from inside");
    delta_case(true, false, true, n, Vec3d(-0.5, 0.3, 0.6), 0.8, "eta below one");
    delta_case(false, false, false, n, wo, 1.5, "plastic coating", true);
    delta_case(false, true, false, n, -wo, 1.4, "two-sided plastic coating from behind", true);
}

// The plastic's coating reflects about the normal with ks times the dielectric's Fresnel
// reflectance, and not at all from behind unless two-sided.
TEST(Specular, PlasticCoatingReflectsWithFresnel) {
    const Vec3d n(0, 0, 1), wo = normalize(Vec3d(0.5, 0.2, 0.6));
    DeltaParams<double> p{Vec3d(1.0, 0.5, 0.25), 1.5, false, false, true};
    Vec3d dir, w;
    ASSERT_TRUE(delta_scatter(p, n, wo, false, 1.0, dir, w));
    const double F = dielectric_reflectance(1.5, n, wo);
    EXPECT_NEAR(dir.x, -wo.x, 1e-12);
    EXPECT_NEAR(dir.z, wo.z, 1e-12);
    EXPECT_NEAR(w.x, F, 1e-12);
    EXPECT_NEAR(w.z, 0.25 * F, 1e-12);
    EXPECT_FALSE(delta_scatter(p, n, -wo, false, 1.0, dir, w));
    EXPECT_FALSE(delta_scatter(p, n, wo, true, 1.0, dir, w));
}

}  // namespace
}  // namespace edgepath
