// Every adjoint against central finite differences in double precision: for a random output
// adjoint y_bar, <y_bar, (f(x + h e_i) - f(x - h e_i)) / 2h> must equal the adjoint's x_bar_i.
#include <gtest/gtest.h>

#include <functional>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "math/frame.h"
#include "scene/bsdf.h"
#include "scene/bsdf_diff.h"
#include "scene/camera.h"
#include "scene/edges.h"
#include "scene/geometry.h"
#include "scene/spot.h"
#include "scene/texture.h"

namespace edgepath {
namespace {

using Fn = std::function<std::vector<double>(const std::vector<double>&)>;

// Checks adjoint(x, ybar) against finite differences of f at x.
void check_adjoint(const Fn& f, const std::function<std::vector<double>(const std::vector<double>&, const std::vector<double>&)>& adjoint,
                   const std::vector<double>& x, const char* what, double h = 1e-6, double tol = 1e-5) {
    std::mt19937 gen(42);
    std::normal_distribution<double> nd;
    std::vector<double> y = f(x);
    std::vector<double> ybar(y.size());
    for (double& v : ybar) v = nd(gen);
    std::vector<double> xbar = adjoint(x, ybar);
    ASSERT_EQ(xbar.size(), x.size());
    double scale = 0;
    for (double v : xbar) scale = std::max(scale, std::abs(v));
    for (size_t i = 0; i < x.size(); ++i) {
        std::vector<double> xp = x, xm = x;
        xp[i] += h;
        xm[i] -= h;
        std::vector<double> yp = f(xp), ym = f(xm);
        double fd = 0;
        for (size_t k = 0; k < y.size(); ++k) fd += ybar[k] * (yp[k] - ym[k]) / (2 * h);
        EXPECT_NEAR(xbar[i], fd, tol * (1 + scale)) << what << ": input " << i;
    }
}

Vec3d v3(const std::vector<double>& x, size_t i) { return Vec3d(x[i], x[i + 1], x[i + 2]); }
void put(std::vector<double>& out, size_t i, const Vec3d& v) { out[i] = v.x; out[i + 1] = v.y; out[i + 2] = v.z; }

// The material's parameters from the inputs x (a coating's table, if any, kept alive in `coat`).
using ParamsOf = std::function<TBsdfParams<double>(const std::vector<double>& x, std::shared_ptr<const CoatTable>& coat)>;

// bsdf_eval_world's adjoint against finite differences. Inputs x: diffuse[3], specular[3],
// alpha, eta (only `with_eta`), n[3], wo[3], wi[3] (the directions normalised inside);
// params_of reads the material's parameters from them.
void check_bsdf_eval_adjoint(const ParamsOf& params_of, bool with_eta, const std::vector<double>& x, const char* name,
                             double h = 1e-6, double tol = 1e-5) {
    const size_t dirs = with_eta ? 8 : 7;  // where n, wo and wi start
    Fn f = [&](const std::vector<double>& x) {
        std::shared_ptr<const CoatTable> coat;
        const TBsdfParams<double> p = params_of(x, coat);
        Vec3d r = bsdf_eval_world(p, v3(x, dirs), v3(x, dirs + 3), v3(x, dirs + 6));
        return std::vector<double>{r.x, r.y, r.z};
    };
    auto adj = [&](const std::vector<double>& x, const std::vector<double>& yb) {
        std::shared_ptr<const CoatTable> coat;
        const TBsdfParams<double> p = params_of(x, coat);
        DBsdf<double> d;
        d_bsdf_eval_world(p, v3(x, dirs), v3(x, dirs + 3), v3(x, dirs + 6), Vec3d(yb[0], yb[1], yb[2]), d);
        std::vector<double> g(dirs + 9);
        put(g, 0, d.diffuse);
        put(g, 3, d.specular);
        g[6] = d.alpha;
        if (with_eta) g[7] = d.eta;
        put(g, dirs, d.n);
        put(g, dirs + 3, d.wo);
        put(g, dirs + 6, d.wi);
        return g;
    };
    check_adjoint(f, adj, x, name, h, tol);
}

// The standard material (diffuse and GGX specular).
void bsdf_case(bool two_sided, Vec3d n, Vec3d wo, Vec3d wi, double alpha, const char* name) {
    auto params_of = [two_sided](const std::vector<double>& x, std::shared_ptr<const CoatTable>&) {
        TBsdfParams<double> p;
        p.diffuse = v3(x, 0);
        p.specular = v3(x, 3);
        p.alpha = x[6];
        p.two_sided = two_sided;
        return p;
    };
    std::vector<double> x = {0.5, 0.3, 0.2, 0.4, 0.2, 0.6, alpha};
    for (const Vec3d& v : {normalize(n), normalize(wo), normalize(wi)}) x.insert(x.end(), {v.x, v.y, v.z});
    check_bsdf_eval_adjoint(params_of, false, x, name);
}

TEST(Adjoint, BsdfEvalWorld) {
    bsdf_case(false, Vec3d(0.1, 0.2, 1), Vec3d(0.3, -0.2, 0.8), Vec3d(-0.4, 0.3, 0.7), 0.3, "glossy");
    bsdf_case(false, Vec3d(0, 0, 1), Vec3d(0.6, 0.1, 0.3), Vec3d(0.2, -0.5, 0.4), 0.08, "grazing, sharp");
    bsdf_case(true, Vec3d(0.1, 0.2, -1), Vec3d(0.3, -0.2, 0.8), Vec3d(-0.4, 0.3, 0.7), 0.5, "two-sided from below");
}

// Smith's G1 of a direction at cosine c to the normal, alpha a: its adjoint against finite
// differences, and in float, finite for directions up to the surface's plane (c down to the
// smallest subnormal), where dG/dc tends to 2 / a and dG/da to 0. (Differentiated through
// tan^2 = 1 / c^2 - 1, it was 0 times infinity below about 1e-13: a light just above a glossy
// floor's plane made every gradient NaN.)
TEST(Adjoint, SmithG1UpToTheSurfacePlane) {
    for (double a : {1e-3, 0.05, 0.3, 1.0})
        for (double c : {0.9, 0.5, 0.1, 1e-3, -0.4}) {
            const double ch = c > 0 ? 0.5 : -0.5;  // the same side of the microfacet
            Fn f = [&](const std::vector<double>& x) { return std::vector<double>{detail::smith_g1(x[0], ch, x[1])}; };
            auto adj = [&](const std::vector<double>& x, const std::vector<double>& yb) {
                double dc = 0, da = 0;
                detail::d_smith_g1(x[0], ch, x[1], yb[0], dc, da);
                return std::vector<double>{dc, da};
            };
            const std::string what = "c " + std::to_string(c) + ", a " + std::to_string(a);
            check_adjoint(f, adj, {c, a}, what.c_str(), 1e-3 * std::min(std::abs(c), a), 1e-4);
        }
    for (float a : {1e-3f, 0.05f, 0.3f, 1.f})
        for (float c : {1e-13f, 1e-20f, 1e-30f, 1e-44f, -1e-30f}) {
            float dc = 0.f, da = 0.f;
            detail::d_smith_g1(c, c > 0.f ? 0.5f : -0.5f, a, 1.f, dc, da);
            EXPECT_TRUE(std::isfinite(dc) && std::isfinite(da)) << "c " << c << ", a " << a;
            EXPECT_NEAR(dc, (c > 0.f ? 2.f : -2.f) / a, 1e-4f * 2.f / a) << "c " << c << ", a " << a;
            EXPECT_NEAR(da, 0.f, 1e-6f) << "c " << c << ", a " << a;
        }
}

// The rough dielectric. Inputs: alpha, eta, n[3], wo[3], wi[3] (normalised inside); cases of
// reflection and transmission from both sides.
void rough_dielectric_case(Vec3d n, Vec3d wo, Vec3d wi, double alpha, double eta, const char* name) {
    auto unpack = [](const std::vector<double>& x, TBsdfParams<double>& p, Vec3d& N, Vec3d& O, Vec3d& I) {
        p.kind = MaterialKind::Dielectric;
        p.rough = true;
        p.two_sided = true;
        p.alpha = x[0];
        p.eta = x[1];
        N = v3(x, 2);
        O = v3(x, 5);
        I = v3(x, 8);
    };
    std::vector<double> x = {alpha, eta};
    for (const Vec3d& v : {normalize(n), normalize(wo), normalize(wi)}) x.insert(x.end(), {v.x, v.y, v.z});
    Fn f = [&](const std::vector<double>& x) {
        TBsdfParams<double> p;
        Vec3d N, O, I;
        unpack(x, p, N, O, I);
        Vec3d r = bsdf_eval_world(p, N, O, I);
        return std::vector<double>{r.x, r.y, r.z};
    };
    {
        TBsdfParams<double> p;
        Vec3d N, O, I;
        unpack(x, p, N, O, I);
        EXPECT_GT(bsdf_eval_world(p, N, O, I).x, 1e-3) << name << ": the case must not be zero";
    }
    auto adj = [&](const std::vector<double>& x, const std::vector<double>& yb) {
        TBsdfParams<double> p;
        Vec3d N, O, I;
        unpack(x, p, N, O, I);
        DBsdf<double> d;
        d_bsdf_eval_world(p, N, O, I, Vec3d(yb[0], yb[1], yb[2]), d);
        std::vector<double> g(11);
        g[0] = d.alpha;
        g[1] = d.eta;
        put(g, 2, d.n);
        put(g, 5, d.wo);
        put(g, 8, d.wi);
        return g;
    };
    check_adjoint(f, adj, x, name);
}

TEST(Adjoint, RoughDielectricEvalWorld) {
    const Vec3d n(0.1, 0.2, 1);
    rough_dielectric_case(n, Vec3d(0.3, -0.2, 0.8), Vec3d(-0.4, 0.3, 0.7), 0.3, 1.5, "reflection outside");
    rough_dielectric_case(n, Vec3d(0.3, -0.2, 0.8), Vec3d(-0.3, 0.1, -0.9), 0.3, 1.5, "transmission inwards");
    rough_dielectric_case(n, Vec3d(0.2, 0.1, -0.9), Vec3d(-0.2, 0.3, 0.8), 0.4, 1.5, "transmission outwards");
    rough_dielectric_case(n, Vec3d(0.2, 0.1, -0.9), Vec3d(-0.3, 0.2, -0.8), 0.25, 1.33, "reflection inside");
    rough_dielectric_case(n, Vec3d(0.6, 0.1, 0.3), Vec3d(-0.5, 0.2, -0.6), 0.1, 1.7, "grazing, sharp");
}

// The plastic (inputs with eta). Its coating's tables are rebuilt for each alpha and eta, so the
// differences in those two see the tabulated function itself (float tables: a coarser step and
// tolerance).
void plastic_case(bool smooth, bool nonlinear, bool two_sided, Vec3d n, Vec3d wo, Vec3d wi, double alpha,
                  double eta, const char* name) {
    auto params_of = [&](const std::vector<double>& x, std::shared_ptr<const CoatTable>& coat) {
        TBsdfParams<double> p;
        p.kind = MaterialKind::Plastic;
        p.diffuse = v3(x, 0);
        p.specular = v3(x, 3);
        p.alpha = x[6];
        p.eta = x[7];
        p.rough = !smooth;
        p.nonlinear = nonlinear;
        p.two_sided = two_sided;
        coat = coat_table(float(x[6]), float(x[7]), smooth);
        p.coat = coat.get();
        return p;
    };
    std::vector<double> x = {0.5, 0.3, 0.2, 0.4, 0.2, 0.6, alpha, eta};
    for (const Vec3d& v : {normalize(n), normalize(wo), normalize(wi)}) x.insert(x.end(), {v.x, v.y, v.z});
    {
        std::shared_ptr<const CoatTable> coat;
        const TBsdfParams<double> p = params_of(x, coat);
        EXPECT_GT(bsdf_eval_world(p, v3(x, 8), v3(x, 11), v3(x, 14)).x, 1e-3) << name << ": the case must not be zero";
    }
    check_bsdf_eval_adjoint(params_of, true, x, name, 1e-4, 1e-3);
}

TEST(Adjoint, PlasticEvalWorld) {
    const Vec3d n(0.1, 0.2, 1);
    plastic_case(false, false, false, n, Vec3d(0.3, -0.2, 0.8), Vec3d(-0.4, 0.3, 0.7), 0.2, 1.5, "rough");
    plastic_case(false, true, false, n, Vec3d(0.6, 0.1, 0.3), Vec3d(0.2, -0.5, 0.4), 0.35, 1.33, "rough, nonlinear");
    plastic_case(true, false, false, n, Vec3d(0.3, -0.2, 0.8), Vec3d(-0.4, 0.3, 0.7), 0.2, 1.5, "smooth");
    plastic_case(false, false, true, Vec3d(0.1, 0.2, -1), Vec3d(0.3, -0.2, 0.8), Vec3d(-0.4, 0.3, 0.7), 0.3, 1.6,
                 "two-sided from below");
}

// The world-space rough dielectric equals the sampler's local model.
TEST(Adjoint, RoughDielectricWorldMatchesLocalModel) {
    BsdfParams p;
    p.kind = MaterialKind::Dielectric;
    p.rough = true;
    p.alpha = 0.3f;
    p.eta = 1.4f;
    TBsdfParams<float> q;
    q.kind = MaterialKind::Dielectric;
    q.rough = true;
    q.alpha = p.alpha;
    q.eta = p.eta;
    const Vec3f n = normalize(Vec3f(0.2f, 0.9f, 0.1f));
    const Frame fr(n);
    const Vec3f wo = normalize(Vec3f(0.3f, 0.8f, -0.2f));
    for (const Vec3f& wi : {normalize(Vec3f(-0.5f, 0.6f, 0.4f)), normalize(Vec3f(-0.2f, -0.9f, 0.3f))}) {
        const Vec3f a = bsdf_eval(p, fr.to_local(wo), fr.to_local(wi)), b = bsdf_eval_world(q, n, wo, wi);
        EXPECT_GT(a.x, 0.f);
        EXPECT_NEAR(a.x, b.x, 1e-5f * (1 + a.x));
    }
}

TEST(Adjoint, BsdfWorldMatchesLocalModel) {
    // The world-space evaluation used by the gradient pass equals the sampler's local model.
    BsdfParams p;
    p.diffuse = Vec3f(0.5f, 0.3f, 0.2f);
    p.specular = Vec3f(0.4f, 0.2f, 0.6f);
    p.alpha = 0.2f;
    TBsdfParams<float> q{p.diffuse, p.specular, p.alpha, false};
    Vec3f n = normalize(Vec3f(0.2f, 0.9f, 0.1f));
    Frame fr(n);
    Vec3f wo = normalize(Vec3f(0.3f, 0.8f, -0.2f)), wi = normalize(Vec3f(-0.5f, 0.6f, 0.4f));
    Vec3f a = bsdf_eval(p, fr.to_local(wo), fr.to_local(wi)), b = bsdf_eval_world(q, n, wo, wi);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(a[c], b[c], 1e-5f * (1 + a[c]));
}

// Inputs: ns[3], wo[3]; ng fixed. Cases: unbent, bent on the front, bent on the back.
// Spot profile: inputs axis[3] (any length), cutoff, beam width, w[3] (used as given). Cases in
// the falloff between the beam and the cutoff, where it has a derivative; inside the beam and
// beyond the cutoff it is flat, and the adjoint must say so.
TEST(Adjoint, SpotFalloff) {
    auto f = [](const std::vector<double>& x) {
        return std::vector<double>{spot_falloff(x.data(), v3(x, 5))};
    };
    auto adjoint = [](const std::vector<double>& x, const std::vector<double>& ybar) {
        std::vector<double> xbar(8, 0.0);
        Vec3d dw(0.0);
        d_spot_falloff(x.data(), v3(x, 5), ybar[0], xbar.data(), dw);
        put(xbar, 5, dw);
        return xbar;
    };
    const Vec3d axis(0.3, -0.2, 1.7);
    const Vec3d u = normalize(axis);
    const Vec3d side = normalize(cross(u, Vec3d(1, 0, 0)));
    int in_falloff = 0;
    for (double angle : {0.1, 0.25, 0.3, 0.34, 0.5, 0.9}) {
        const Vec3d w = u * std::cos(angle) + side * std::sin(angle);
        std::vector<double> x = {axis.x, axis.y, axis.z, 0.35, 0.2, w.x, w.y, w.z};
        const double value = f(x)[0];
        if (value > 0.0 && value < 1.0) ++in_falloff;
        check_adjoint(f, adjoint, x, "spot_falloff");
    }
    EXPECT_EQ(in_falloff, 3);
    // A wide spot (cutoff past 90 degrees) with no beam: the falloff reaches the axis.
    const Vec3d w = u * std::cos(2.0) + side * std::sin(2.0);
    check_adjoint(f, adjoint, {axis.x, axis.y, axis.z, 2.5, 0.0, w.x, w.y, w.z}, "spot_falloff wide");
}

TEST(Adjoint, BendNormal) {
    const Vec3d ng(0, 0, 1);
    struct Case {
        Vec3d ns, wo;
        bool bent;
    };
    for (const Case& c : {Case{normalize(Vec3d(0.2, 0.1, 1)), normalize(Vec3d(0.3, -0.2, 1)), false},
                          Case{normalize(Vec3d(0.6, 0, 0.8)), normalize(Vec3d(-0.9, 0.1, 0.2)), true},
                          Case{normalize(Vec3d(0.6, 0, 0.8)), normalize(Vec3d(0.9, 0.1, -0.2)), true}}) {
        const Vec3d b = bend_normal(c.ns, ng, c.wo);
        EXPECT_EQ(c.bent, length(b - c.ns) > 1e-12);
        // the viewer is on the face's side of the bent normal, by at least about the margin
        const double s = dot(c.wo, ng) < 0 ? -1 : 1;
        EXPECT_GE(s * dot(c.wo, b), 0.9 * kMinShadingCosine);
        std::vector<double> x = {c.ns.x, c.ns.y, c.ns.z, c.wo.x, c.wo.y, c.wo.z};
        Fn f = [&](const std::vector<double>& x) {
            Vec3d o = bend_normal(v3(x, 0), ng, v3(x, 3));
            return std::vector<double>{o.x, o.y, o.z};
        };
        auto adj = [&](const std::vector<double>& x, const std::vector<double>& ybar) {
            Vec3d dns(0.0), dwo(0.0);
            d_bend_normal(v3(x, 0), ng, v3(x, 3), v3(ybar, 0), dns, dwo);
            std::vector<double> out(6);
            put(out, 0, dns);
            put(out, 3, dwo);
            return out;
        };
        check_adjoint(f, adj, x, "bend_normal");
    }
}

// A smooth lobe's direction kept on its side of the face (scene/specular.h): the adjoint in the
// direction and the geometric normal (inputs dir, ng; ng normalised inside, as a face's is),
// where it is kept and where it is mirrored; continuity across the face's plane; the side.
TEST(Adjoint, DeltaSide) {
    struct Case {
        Vec3d dir, ng;
        double side;
        bool mirrored;
    };
    const Vec3d ng = normalize(Vec3d(0.1, -0.2, 1));
    for (const Case& c : {Case{normalize(Vec3d(0.3, 0.2, 0.5)), ng, 1, false},
                          Case{normalize(Vec3d(0.3, 0.2, -0.5)), ng, 1, true},
                          Case{normalize(Vec3d(-0.7, 0.4, 0.3)), ng, -1, true},
                          Case{normalize(Vec3d(-0.7, 0.4, -0.3)), ng, -1, false}}) {
        const Vec3d out = delta_side(c.dir, c.ng, c.side);
        EXPECT_EQ(c.mirrored, length(out - c.dir) > 1e-12);
        EXPECT_GE(c.side * dot(out, c.ng), 0.0);
        EXPECT_NEAR(length(out), 1.0, 1e-12);
        Fn f = [&](const std::vector<double>& x) {
            const Vec3d o = delta_side(v3(x, 0), normalize(v3(x, 3)), c.side);
            return std::vector<double>{o.x, o.y, o.z};
        };
        auto adj = [&](const std::vector<double>& x, const std::vector<double>& ybar) {
            Vec3d ddir(0.0), dng(0.0);
            const bool mirrored = d_delta_side(v3(x, 0), normalize(v3(x, 3)), c.side, v3(ybar, 0), ddir, dng);
            EXPECT_EQ(c.mirrored, mirrored);
            std::vector<double> out(6);
            put(out, 0, ddir);
            put(out, 3, d_normalize(v3(x, 3), dng));
            return out;
        };
        check_adjoint(f, adj, {c.dir.x, c.dir.y, c.dir.z, c.ng.x, c.ng.y, c.ng.z}, "delta_side");
    }
    // Continuous where the direction crosses the plane: a direction just above it and its mirror
    // image just below give the same output.
    const Vec3d t = normalize(cross(ng, Vec3d(1, 0, 0)));
    for (double e : {1e-3, 1e-6}) {
        const Vec3d above = normalize(t + ng * e), below = normalize(t - ng * e);
        EXPECT_LT(length(delta_side(above, ng, 1.0) - delta_side(below, ng, 1.0)), 1e-9);
        EXPECT_LT(length(delta_side(above, ng, -1.0) - delta_side(below, ng, -1.0)), 1e-9);
    }
    // The side: a reflection leaves on wo's side, a refraction on the other.
    const Vec3d front = normalize(Vec3d(0.2, 0.3, 1)), back = -front;
    EXPECT_EQ(delta_side_sign(front, ng, false), 1.0);
    EXPECT_EQ(delta_side_sign(front, ng, true), -1.0);
    EXPECT_EQ(delta_side_sign(back, ng, false), -1.0);
    EXPECT_EQ(delta_side_sign(back, ng, true), 1.0);
}

// The side function of an edge, g = dot(cross(e0 - o, e1 - o), d): inputs e0, e1, o, d.
TEST(Adjoint, EdgeSideFunction) {
    std::vector<double> x = {0.3, -0.2, 2.0, -0.4, 0.5, 2.5, 0.1, 0.2, -1.0, 0.05, 0.1, 1.0};
    Fn f = [](const std::vector<double>& x) {
        return std::vector<double>{dot(cross(v3(x, 0) - v3(x, 6), v3(x, 3) - v3(x, 6)), v3(x, 9))};
    };
    auto adj = [](const std::vector<double>& x, const std::vector<double>& ybar) {
        const EdgeSideGradient g = edge_side_gradient(Vec3f(v3(x, 0)), Vec3f(v3(x, 3)), Vec3f(v3(x, 6)), Vec3f(v3(x, 9)));
        std::vector<double> out(12);
        put(out, 0, Vec3d(g.d_e0) * ybar[0]);
        put(out, 3, Vec3d(g.d_e1) * ybar[0]);
        put(out, 6, Vec3d(g.d_o) * ybar[0]);
        put(out, 9, Vec3d(g.d_d) * ybar[0]);
        return out;
    };
    check_adjoint(f, adj, x, "edge side function", 1e-6, 1e-5);
}

TEST(Adjoint, IntersectTriangle) {
    std::vector<double> x = {0.1, 0.2, -3, 0.05, -0.02, 1, -1, -1, 0.2, 1.2, -0.8, 0.1, 0.1, 1.1, -0.3};
    auto unpack = [](const std::vector<double>& x, Vec3d* a) { for (int k = 0; k < 5; ++k) a[k] = v3(x, 3 * k); };
    Fn f = [&](const std::vector<double>& x) {
        Vec3d a[5];
        unpack(x, a);
        TriangleHit<double> h;
        intersect_triangle(a[0], a[1], a[2], a[3], a[4], h);
        return std::vector<double>{h.t, h.b1, h.b2};
    };
    auto adj = [&](const std::vector<double>& x, const std::vector<double>& yb) {
        Vec3d a[5];
        unpack(x, a);
        TriangleHit<double> h;
        intersect_triangle(a[0], a[1], a[2], a[3], a[4], h);
        DTriangle<double> g{};
        d_intersect_triangle(a[0], a[1], a[2], a[3], a[4], h, yb[0], yb[1], yb[2], g);
        std::vector<double> out(15);
        put(out, 0, g.o);
        put(out, 3, g.d);
        put(out, 6, g.v0);
        put(out, 9, g.v1);
        put(out, 12, g.v2);
        return out;
    };
    check_adjoint(f, adj, x, "intersect_triangle");
}

void camera_case(CameraType type, float lu = kLensCentre, float lv = kLensCentre, double fov = 40,
                 double px = 13.3, double py = 40.7) {
    // Inputs: position, look_at, up, fov, ortho_scale, aperture_radius, focus_distance; outputs:
    // origin, direction.
    std::vector<double> x = {0.3, 0.5, -4, 0.1, -0.2, 0.3, 0.1, 1, 0.2, fov, 1.5, 0.3, 2.5};
    auto unpack = [type](const std::vector<double>& x) {
        TCameraParams<double> c;
        c.position = v3(x, 0);
        c.look_at = v3(x, 3);
        c.up = v3(x, 6);
        c.fov = x[9];
        c.ortho_scale = x[10];
        c.aperture_radius = x[11];
        c.focus_distance = x[12];
        c.type = type;
        c.width = 64;
        c.height = 48;
        return c;
    };
    Fn f = [&](const std::vector<double>& x) {
        Vec3d o, d;
        camera_ray(unpack(x), px, py, lu, lv, o, d);
        return std::vector<double>{o.x, o.y, o.z, d.x, d.y, d.z};
    };
    auto adj = [&](const std::vector<double>& x, const std::vector<double>& yb) {
        std::vector<double> g(kCameraParams, 0.0);
        d_camera_ray(unpack(x), px, py, lu, lv, v3(yb, 0), v3(yb, 3), g.data());
        return g;
    };
    const char* names[] = {"perspective", "orthographic", "thin lens", "fisheye", "panorama"};
    check_adjoint(f, adj, x, names[int(type)]);
}

TEST(Adjoint, CameraRay) {
    camera_case(CameraType::Perspective);
    camera_case(CameraType::Orthographic);
    // Lens samples off the centre, in each quadrant of the concentric map.
    camera_case(CameraType::ThinLens, 0.8f, 0.35f);
    camera_case(CameraType::ThinLens, 0.1f, 0.7f);
    camera_case(CameraType::ThinLens, 0.3f, 0.05f);
    // Fisheyes narrower and wider than a half sphere, off and near the centre of the film;
    // a panorama's film point above the horizon and one below, behind the camera.
    camera_case(CameraType::Fisheye, kLensCentre, kLensCentre, 40);
    camera_case(CameraType::Fisheye, kLensCentre, kLensCentre, 250);
    camera_case(CameraType::Fisheye, kLensCentre, kLensCentre, 190, 32.01, 24.02);
    camera_case(CameraType::Panorama);
    camera_case(CameraType::Panorama, kLensCentre, kLensCentre, 40, 61.5, 5.2);
}

TEST(Adjoint, SphericalCamerasMatchRenderCamera) {
    CameraDesc d;
    float pos[3] = {0.3f, 0.5f, -4.f}, at[3] = {0.1f, -0.2f, 0.3f}, up[3] = {0.1f, 1.f, 0.2f};
    std::copy(pos, pos + 3, d.position);
    std::copy(at, at + 3, d.look_at);
    std::copy(up, up + 3, d.up);
    d.width = 64;
    d.height = 48;
    for (CameraType type : {CameraType::Fisheye, CameraType::Panorama}) {
        d.type = type;
        d.fov = 230;
        const Camera cam = Camera::from_desc(d);
        const Ray r = cam.generate_ray(13.3f, 40.7f);
        Vec3d o, dir;
        camera_ray(TCameraParams<double>::from_desc(d), 13.3, 40.7, o, dir);
        for (int k = 0; k < 3; ++k) {
            EXPECT_NEAR(r.origin[k], o[k], 1e-5);
            EXPECT_NEAR(r.dir[k], dir[k], 1e-5);
        }
        EXPECT_NEAR(length(dir), 1.0, 1e-12);
        // The film's centre looks along forward; a fisheye's film edge at half its fov from it.
        const Ray c = cam.generate_ray(32.f, 24.f);
        EXPECT_NEAR(dot(c.dir, cam.forward), 1.f, 1e-6f);
        if (type == CameraType::Fisheye) {
            EXPECT_NEAR(std::acos(double(dot(cam.generate_ray(64.f, 24.f).dir, cam.forward))), 115.0 * kCameraPi / 180.0, 1e-4);
            EXPECT_TRUE(cam.sees(64.f, 24.f));
            EXPECT_FALSE(cam.sees(63.f, 1.f));  // a corner: outside the image circle
        } else {
            // The film's left and right edges look backwards, its top row up.
            EXPECT_NEAR(dot(cam.generate_ray(0.f, 24.f).dir, cam.forward), -1.f, 1e-6f);
            EXPECT_NEAR(dot(cam.generate_ray(17.f, 0.f).dir, cam.up), 1.f, 1e-6f);
            EXPECT_NEAR(dot(cam.generate_ray(48.f, 24.f).dir, cam.right), 1.f, 1e-6f);  // a quarter turn right
            EXPECT_TRUE(cam.sees(63.f, 1.f));
        }
    }
}

TEST(Adjoint, CameraRayMatchesRenderCamera) {
    CameraDesc d;
    float pos[3] = {0.3f, 0.5f, -4.f}, at[3] = {0.1f, -0.2f, 0.3f}, up[3] = {0.1f, 1.f, 0.2f};
    std::copy(pos, pos + 3, d.position);
    std::copy(at, at + 3, d.look_at);
    std::copy(up, up + 3, d.up);
    d.fov = 40;
    d.width = 64;
    d.height = 48;
    Ray r = Camera::from_desc(d).generate_ray(13.3f, 40.7f);
    Vec3d o, dir;
    camera_ray(TCameraParams<double>::from_desc(d), 13.3, 40.7, o, dir);
    for (int k = 0; k < 3; ++k) {
        EXPECT_NEAR(r.origin[k], o[k], 1e-5);
        EXPECT_NEAR(r.dir[k], dir[k], 1e-5);
    }
    // A thin lens: a ray from the aperture through the film point's point in focus.
    d.type = CameraType::ThinLens;
    d.aperture_radius = 0.25f;
    d.focus_distance = 3.f;
    const Camera cam = Camera::from_desc(d);
    r = cam.generate_ray(13.3f, 40.7f, 0.9f, 0.2f);
    camera_ray(TCameraParams<double>::from_desc(d), 13.3, 40.7, 0.9f, 0.2f, o, dir);
    for (int k = 0; k < 3; ++k) {
        EXPECT_NEAR(r.origin[k], o[k], 1e-5);
        EXPECT_NEAR(r.dir[k], dir[k], 1e-5);
    }
    EXPECT_GT(length(r.origin - cam.position), 0.1f);  // off the centre
    EXPECT_LE(length(r.origin - cam.position), 0.25f + 1e-6f);
    // Every lens point's ray through a film point meets the pinhole's on the plane of focus.
    const Ray pin = cam.generate_ray(13.3f, 40.7f);
    const float t_pin = 3.f / dot(pin.dir, cam.forward), t_lens = dot(pin.origin + pin.dir * t_pin - r.origin, cam.forward) / dot(r.dir, cam.forward);
    const Vec3f gap = (pin.origin + pin.dir * t_pin) - (r.origin + r.dir * t_lens);
    EXPECT_LT(length(gap), 1e-5f);
}

TEST(Adjoint, TextureFootprintUvDerivative) {
    std::vector<float> data(5 * 4 * 1);
    for (size_t i = 0; i < data.size(); ++i) data[i] = float((i * 37) % 11) * 0.1f;
    Texture tex;
    tex.data = data.data();
    tex.height = 4;
    tex.width = 5;
    tex.channels = 1;
    Vec2f uv(0.43f, 0.71f);
    TexelFootprint f = bilinear_footprint(tex, uv);
    double du = 0, dv = 0;
    for (int k = 0; k < 4; ++k) {
        du += f.dweight_du[k] * data[f.texel[k]];
        dv += f.dweight_dv[k] * data[f.texel[k]];
    }
    const float h = 1e-3f;
    double fd_u = (eval_texture1(tex, Vec2f(uv.x + h, uv.y)) - eval_texture1(tex, Vec2f(uv.x - h, uv.y))) / (2 * h);
    double fd_v = (eval_texture1(tex, Vec2f(uv.x, uv.y + h)) - eval_texture1(tex, Vec2f(uv.x, uv.y - h))) / (2 * h);
    EXPECT_NEAR(du, fd_u, 1e-2);
    EXPECT_NEAR(dv, fd_v, 1e-2);
    float wsum = 0;
    for (int k = 0; k < 4; ++k) wsum += f.weight[k];
    EXPECT_NEAR(wsum, 1.f, 1e-6f);
}

}  // namespace
}  // namespace edgepath
