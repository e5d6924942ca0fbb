// Building blocks of the forward renderer: densities integrate to one, samplers agree with their
// densities, estimators agree with direct integration.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "sampling/distribution.h"
#include "sampling/rng.h"
#include "sampling/spherical_triangle.h"
#include "sampling/warp.h"
#include "scene/bsdf.h"
#include "scene/envmap.h"
#include "scene/filter.h"
#include "scene/geometry.h"

namespace edgepath {
namespace {

// Mean and standard error of a stream of values.
struct Acc {
    double s = 0, s2 = 0;
    long n = 0;
    void add(double v) { s += v; s2 += v * v; ++n; }
    double mean() const { return s / n; }
    double se() const { return std::sqrt(std::max(0.0, s2 / n - mean() * mean()) / n); }
};

std::vector<BsdfParams> test_materials() {
    std::vector<BsdfParams> v;
    BsdfParams p;
    p.diffuse = Vec3f(0.8f, 0.5f, 0.2f); p.specular = Vec3f(0.f); p.alpha = 0.5f;
    v.push_back(p);
    p.diffuse = Vec3f(0.f); p.specular = Vec3f(0.9f, 0.6f, 0.3f); p.alpha = 0.3f;
    v.push_back(p);
    p.diffuse = Vec3f(0.4f); p.specular = Vec3f(0.3f); p.alpha = 0.15f;
    v.push_back(p);
    p.two_sided = true;  // evaluated from below
    v.push_back(p);
    return v;
}

TEST(Bsdf, PdfIntegratesToOneAndSamplerMatchesIntegral) {
    Rng rng(7, 1);
    int idx = 0;
    for (const BsdfParams& p : test_materials()) {
        Vec3f wo = normalize(Vec3f(0.4f, -0.2f, p.two_sided ? -0.8f : 0.8f));
        Acc pdf_int, success, f_uniform[3], f_sampled[3];
        const int N = 400000;
        for (int i = 0; i < N; ++i) {
            Vec3f w = square_to_sphere(rng.next_float(), rng.next_float());
            float inv_pdf = 4.f * kPi;
            pdf_int.add(bsdf_pdf(p, wo, w) * inv_pdf);
            Vec3f f = bsdf_eval(p, wo, w) * inv_pdf;
            for (int c = 0; c < 3; ++c) f_uniform[c].add(f[c]);
            BsdfSample bs;
            Vec3f g(0.f);
            bool ok = bsdf_sample(p, wo, rng.next_float(), rng.next_float(), rng.next_float(), bs);
            success.add(ok ? 1.0 : 0.0);
            if (ok) {
                float pdf = bsdf_pdf(p, wo, bs.wi);
                EXPECT_NEAR(pdf, bs.pdf, 1e-3f * pdf + 1e-6f);
                g = bsdf_eval(p, wo, bs.wi) / bs.pdf;
            }
            for (int c = 0; c < 3; ++c) f_sampled[c].add(g[c]);
        }
        // The density integrates to the probability that sampling succeeds (GGX samples that
        // fall below the horizon are discarded).
        EXPECT_NEAR(pdf_int.mean(), success.mean(), 5 * std::hypot(pdf_int.se(), success.se())) << "material " << idx;
        if (is_black(p.specular)) {
            EXPECT_EQ(success.mean(), 1.0);
        }
        for (int c = 0; c < 3; ++c) {
            double se = std::hypot(f_uniform[c].se(), f_sampled[c].se());
            EXPECT_NEAR(f_uniform[c].mean(), f_sampled[c].mean(), 5 * se + 1e-6) << "material " << idx;
            EXPECT_LE(f_sampled[c].mean(), 1.0 + 5 * se) << "energy gain, material " << idx;
        }
        ++idx;
    }
}

// The rough dielectric reflects and transmits, from outside (eta) and inside (1 / eta): its
// density integrates to the probability that sampling succeeds, its sampler's estimate agrees
// with uniform sampling of the sphere, and with a small roughness the total weight approaches
// the smooth interface's F + (1 - F) / e^2 (radiance, e the index ratio across it).
TEST(Bsdf, RoughDielectricSamplerMatchesIntegralAndSmoothLimit) {
    Rng rng(11, 3);
    struct Case { float alpha, eta, wz; };
    for (const Case& c : {Case{0.3f, 1.5f, 0.8f}, Case{0.3f, 1.5f, -0.8f}, Case{0.6f, 1.33f, 0.4f},
                          Case{0.2f, 1.5f, -0.5f}}) {
        BsdfParams p;
        p.kind = MaterialKind::Dielectric;
        p.rough = true;
        p.two_sided = true;
        p.alpha = c.alpha;
        p.eta = c.eta;
        const Vec3f wo = normalize(Vec3f(0.4f, -0.2f, c.wz));
        Acc pdf_int, success, f_uniform, f_sampled, transmitted;
        const int N = 400000;
        for (int i = 0; i < N; ++i) {
            const Vec3f w = square_to_sphere(rng.next_float(), rng.next_float());
            pdf_int.add(bsdf_pdf(p, wo, w) * 4.f * kPi);
            const Vec3f f = bsdf_eval(p, wo, w);
            EXPECT_EQ(f.x, f.z);
            f_uniform.add(f.x * 4.f * kPi);
            BsdfSample bs;
            double g = 0, t = 0;
            const bool ok = bsdf_sample(p, wo, rng.next_float(), rng.next_float(), rng.next_float(), bs);
            success.add(ok ? 1.0 : 0.0);
            if (ok) {
                EXPECT_FALSE(bs.delta);
                const float pdf = bsdf_pdf(p, wo, bs.wi);
                EXPECT_NEAR(pdf, bs.pdf, 1e-3f * pdf + 1e-6f);
                g = bsdf_eval(p, wo, bs.wi).x / bs.pdf;
                if (bs.wi.z * wo.z < 0.f) t = g;
            }
            f_sampled.add(g);
            transmitted.add(t);
        }
        EXPECT_GT(transmitted.mean(), 0.3) << "alpha " << c.alpha << " wz " << c.wz;
        EXPECT_NEAR(pdf_int.mean(), success.mean(), 5 * std::hypot(pdf_int.se(), success.se()));
        const double se = std::hypot(f_uniform.se(), f_sampled.se());
        EXPECT_NEAR(f_uniform.mean(), f_sampled.mean(), 5 * se + 1e-6) << "alpha " << c.alpha << " wz " << c.wz;
    }
    for (float wz : {0.7f, -0.9f}) {
        BsdfParams p;
        p.kind = MaterialKind::Dielectric;
        p.rough = true;
        p.alpha = 0.01f;
        p.eta = 1.5f;
        const Vec3f wo = normalize(Vec3f(0.3f, 0.1f, wz));
        const float F = dielectric_reflectance(p.eta, Vec3f(0.f, 0.f, 1.f), wo);
        const float e = wz > 0.f ? p.eta : 1.f / p.eta;
        const double expected = F + (F < 1.f ? (1.f - F) / (e * e) : 0.f);
        Acc sum;
        for (int i = 0; i < 100000; ++i) {
            BsdfSample bs;
            double g = 0;
            if (bsdf_sample(p, wo, rng.next_float(), rng.next_float(), rng.next_float(), bs))
                g = bsdf_eval(p, wo, bs.wi).x / bs.pdf;
            sum.add(g);
        }
        EXPECT_NEAR(sum.mean(), expected, 0.02 * expected) << "wz " << wz;
    }
}

// The plastic against Mitsuba 3's `roughplastic` (ggx, alpha 0.2) and `plastic`, both with
// int_ior 1.5, diffuse_reflectance 0.5 and specular_reflectance 1: bsdf.eval of Mitsuba 3.9.1's
// scalar_rgb variant (f times the light's cosine) with the viewer at theta_v, phi 0 and the
// light at theta_l, phi 250 degrees; the whole BSDF and its diffuse component alone.
TEST(Bsdf, PlasticMatchesMitsuba) {
    struct Case { float theta_v, theta_l; double rough_total, rough_diffuse, smooth; };
    const Case cases[] = {{10, 60, 0.061086, 0.0592165, 0.0766995},
                          {45, 20, 0.121871, 0.116048, 0.150272},
                          {70, 30, 0.0982163, 0.0954684, 0.120718},
                          {30, 80, 0.0177393, 0.0170726, 0.017879}};
    auto dir = [](float theta, float phi) {
        const float t = theta * kPi / 180.f, p = phi * kPi / 180.f;
        return Vec3f(std::sin(t) * std::cos(p), std::sin(t) * std::sin(p), std::cos(t));
    };
    for (bool smooth : {false, true}) {
        const auto coat = coat_table(0.2f, 1.5f, smooth);
        BsdfParams p;
        p.kind = MaterialKind::Plastic;
        p.diffuse = Vec3f(0.5f);
        p.specular = Vec3f(1.f);
        p.alpha = 0.2f;
        p.eta = 1.5f;
        p.rough = !smooth;
        p.coat = coat.get();
        BsdfParams base = p;
        base.specular = Vec3f(0.f);
        for (const Case& c : cases) {
            const Vec3f wo = dir(c.theta_v, 0.f), wi = dir(c.theta_l, 250.f);
            const float total = bsdf_eval(p, wo, wi).x, diffuse = bsdf_eval(base, wo, wi).x;
            if (smooth) {
                EXPECT_NEAR(total, c.smooth, 2e-4 * c.smooth) << c.theta_v << " " << c.theta_l;
            } else {
                // The tables: Gauss-Legendre quadrature as Mitsuba's, over our visible normals.
                EXPECT_NEAR(total, c.rough_total, 2e-3 * c.rough_total) << c.theta_v << " " << c.theta_l;
                EXPECT_NEAR(diffuse, c.rough_diffuse, 2e-3 * c.rough_diffuse) << c.theta_v << " " << c.theta_l;
            }
        }
    }
    // The internal reflectance of the rough coating (alpha 0.2, eta 1.5): about 0.49.
    EXPECT_NEAR(coat_table(0.2f, 1.5f, false)->r, 0.486, 0.002);
}

// The plastic's density integrates to the probability that sampling succeeds; its sampler's
// estimate agrees with uniform sampling of the sphere (with the smooth coating, plus the
// expected weight of its mirror lobe, ks F(cos theta_o)); it does not gain energy.
TEST(Bsdf, PlasticSamplerMatchesIntegral) {
    Rng rng(13, 5);
    struct Case { bool smooth, two_sided; float alpha, eta, wz; Vec3f kd, ks; };
    for (const Case& c : {Case{false, false, 0.2f, 1.5f, 0.8f, Vec3f(0.8f, 0.5f, 0.2f), Vec3f(1.f)},
                          Case{false, true, 0.5f, 1.33f, -0.3f, Vec3f(0.3f), Vec3f(0.6f, 0.8f, 1.f)},
                          Case{true, false, 0.f, 1.5f, 0.7f, Vec3f(0.8f, 0.5f, 0.2f), Vec3f(1.f)},
                          Case{true, true, 0.f, 1.6f, -0.25f, Vec3f(0.9f), Vec3f(0.5f)}}) {
        const auto coat = coat_table(std::max(c.alpha, kMinRoughness), c.eta, c.smooth);
        BsdfParams p;
        p.kind = MaterialKind::Plastic;
        p.diffuse = c.kd;
        p.specular = c.ks;
        p.alpha = std::max(c.alpha, kMinRoughness);
        p.eta = c.eta;
        p.rough = !c.smooth;
        p.two_sided = c.two_sided;
        p.coat = coat.get();
        const Vec3f wo = normalize(Vec3f(0.4f, -0.2f, c.wz));
        Acc pdf_int, success, f_uniform[3], f_sampled[3], delta;
        const int N = 400000;
        for (int i = 0; i < N; ++i) {
            const Vec3f w = square_to_sphere(rng.next_float(), rng.next_float());
            pdf_int.add(bsdf_pdf(p, wo, w) * 4.f * kPi);
            const Vec3f f = bsdf_eval(p, wo, w) * (4.f * kPi);
            for (int k = 0; k < 3; ++k) f_uniform[k].add(f[k]);
            BsdfSample bs;
            Vec3f g(0.f);
            const bool ok = bsdf_sample(p, wo, rng.next_float(), rng.next_float(), rng.next_float(), bs);
            success.add(ok && !bs.delta ? 1.0 : 0.0);
            delta.add(ok && bs.delta ? 1.0 : 0.0);
            if (ok && bs.delta) {
                EXPECT_TRUE(c.smooth);
                EXPECT_NEAR(bs.wi.z, wo.z, 1e-6f);
                EXPECT_NEAR(bs.wi.x, -wo.x, 1e-6f);
                g = bs.weight;
            } else if (ok) {
                const float pdf = bsdf_pdf(p, wo, bs.wi);
                EXPECT_NEAR(pdf, bs.pdf, 1e-3f * pdf + 1e-6f);
                g = bsdf_eval(p, wo, bs.wi) / bs.pdf;
            }
            for (int k = 0; k < 3; ++k) f_sampled[k].add(g[k]);
        }
        const float F = dielectric_reflectance(c.eta, Vec3f(0.f, 0.f, 1.f), Vec3f(wo.x, wo.y, std::abs(wo.z)));
        EXPECT_NEAR(pdf_int.mean(), success.mean(), 5 * std::hypot(pdf_int.se(), success.se())) << c.wz;
        if (c.smooth) {
            EXPECT_GT(delta.mean(), 0.01);
        }
        for (int k = 0; k < 3; ++k) {
            const double mirror = c.smooth ? double(c.ks[k] * F) : 0.0;
            const double se = std::hypot(f_uniform[k].se(), f_sampled[k].se());
            EXPECT_NEAR(f_uniform[k].mean() + mirror, f_sampled[k].mean(), 5 * se + 1e-6) << c.wz << " channel " << k;
            EXPECT_LE(f_sampled[k].mean(), 1.0 + 5 * se) << "energy gain " << c.wz;
        }
    }
}

TEST(Bsdf, OneSidedIsBlackFromBelowAndReciprocal) {
    BsdfParams p = test_materials()[2];
    Vec3f a = normalize(Vec3f(0.3f, 0.1f, 0.9f)), b = normalize(Vec3f(-0.5f, 0.2f, 0.6f));
    Vec3f below(a.x, a.y, -a.z);
    EXPECT_TRUE(is_black(bsdf_eval(p, below, b)));
    EXPECT_TRUE(is_black(bsdf_eval(p, b, below)));
    EXPECT_EQ(bsdf_pdf(p, below, b), 0.f);
    // f(a, b) cos(b) / cos(b) == f(b, a) cos(a) / cos(a)
    Vec3f fab = bsdf_eval(p, a, b) / b.z, fba = bsdf_eval(p, b, a) / a.z;
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(fab[c], fba[c], 1e-5f * fab[c]);
}

// A pixel's samples are independent: the mean over a pixel's n samples of an event of their
// first random numbers varies across pixels as a binomial proportion's does. Streams that
// shared one starting state (only the increment told them apart) gave variances 0.23 to 0.63
// times that at n = 4096, 0.28 times at 20,000, for the events below (and a glass slab's
// transmission at 20,000 spp 3.5 times its binomial variance).
TEST(Rng, APixelsSamplesAreIndependent) {
    const int pixels = 300;
    for (int n : {1024, 4096, 20000}) {
        for (int event = 0; event < 3; ++event) {
            std::vector<double> means;
            double p = 0.0;
            for (int px = 0; px < pixels; ++px) {
                long hits = 0;
                for (int s = 0; s < n; ++s) {
                    Rng rng = Rng::for_sample(11, uint64_t(px), uint64_t(s));
                    float u[4];
                    for (float& x : u) x = rng.next_float();
                    const bool hit = event == 0 ? u[0] < 0.1f : event == 1 ? u[3] < 0.5f : (u[1] < 0.3f && u[2] < 0.3f);
                    hits += hit ? 1 : 0;
                }
                means.push_back(double(hits) / n);
                p += double(hits) / n / pixels;
            }
            double var = 0.0;
            for (double m : means) var += (m - p) * (m - p) / (pixels - 1);
            // The ratio's own standard deviation is about sqrt(2 / 299) = 0.08.
            const double ratio = var / (p * (1 - p) / n);
            EXPECT_GT(ratio, 0.6) << "n " << n << ", event " << event;
            EXPECT_LT(ratio, 1.5) << "n " << n << ", event " << event;
        }
    }
}

TEST(Distribution, SamplesFollowWeights) {
    Distribution1D d({1.0, 0.0, 3.0, 4.0});
    std::vector<int> count(4, 0);
    Rng rng(3, 2);
    const int N = 200000;
    for (int i = 0; i < N; ++i) {
        float u = rng.next_float();
        int k = d.sample(u);
        ASSERT_GE(u, 0.f);
        ASSERT_LT(u, 1.f);
        ++count[k];
    }
    EXPECT_EQ(count[1], 0);
    for (int k = 0; k < 4; ++k) {
        double p = d.pmf(k);
        EXPECT_NEAR(count[k] / double(N), p, 5 * std::sqrt(p * (1 - p) / N) + 1e-9);
    }
}

// Distribution1D's cdf as build() computes it, for weights w.
std::vector<double> distribution_cdf(const std::vector<double>& w) {
    const size_t n = w.size();
    std::vector<double> cdf(n + 1, 0.0);
    for (size_t i = 0; i < n; ++i) cdf[i + 1] = cdf[i] + w[i];
    const double total = cdf[n];
    for (size_t i = 0; i < n; ++i) cdf[i + 1] /= total;
    cdf[n] = 1.0;
    return cdf;
}

// Numbers to sample with: `extra`, `count` from rng, and each cdf entry's float with its two
// neighbours (those in [0, 1)).
std::vector<float> border_numbers(const std::vector<double>& cdf, Rng& rng, int count, std::vector<float> extra = {}) {
    std::vector<float> us = std::move(extra);
    for (int k = 0; k < count; ++k) us.push_back(rng.next_float());
    for (double entry : cdf) {
        const float c = float(entry);
        for (float u : {c, std::nextafter(c, 0.f), std::nextafter(c, 1.f)})
            if (u >= 0.f && u < 1.f) us.push_back(u);
    }
    return us;
}

// The bin a binary search over cdf picks for u (an empty bin's pick moved down to the nearest
// non-empty one below, as Distribution1D does).
int binary_search_bin(const std::vector<double>& cdf, const Distribution1D& d, double u) {
    const int n = int(cdf.size()) - 1;
    int bin = std::clamp(int(std::upper_bound(cdf.begin(), cdf.end(), u) - cdf.begin()) - 1, 0, n - 1);
    while (d.pmf(bin) == 0.f && bin > 0) --bin;
    return bin;
}

// The guide table picks the bin a binary search over the same cdf picks, for skewed weights
// (one bin holding almost everything, runs of empty bins) and for u at the bins' borders.
TEST(Distribution, GuideTableAgreesWithBinarySearch) {
    Rng rng(5, 1);
    for (int trial = 0; trial < 40; ++trial) {
        const int n = 1 + int(rng.next_float() * 300.f);
        std::vector<double> w(static_cast<size_t>(n), 0.0);
        for (int i = 0; i < n; ++i) {
            const float r = rng.next_float();
            w[size_t(i)] = r < 0.3f ? 0.0 : (r < 0.35f ? 1e6 : double(rng.next_float()));
        }
        if (trial % 2 == 0) w[size_t(n / 2)] = 1e9;
        const Distribution1D d(w);
        const std::vector<double> cdf = distribution_cdf(w);
        for (float u0 : border_numbers(cdf, rng, 2000)) {
            float u = u0;
            ASSERT_EQ(d.sample(u), binary_search_bin(cdf, d, u0)) << "n " << n << " u " << u0;
        }
    }
}

// A distribution of a few bins (a light of one or a few quads) counts the cdf entries at or
// below u rather than walking from the guide table: the same bin as a binary search, and the
// same position inside it, for weights with empty bins and plateaus and u at the bins' borders.
TEST(Distribution, FewBinsAgreeWithBinarySearch) {
    Rng rng(9, 3);
    for (int trial = 0; trial < 400; ++trial) {
        const int n = 1 + trial % 10;  // 1 to 8 counted, 9 and 10 walked
        std::vector<double> w(static_cast<size_t>(n), 0.0);
        for (int i = 0; i < n; ++i) {
            const float r = rng.next_float();
            w[size_t(i)] = r < 0.3f ? 0.0 : (r < 0.4f ? 1e7 : double(rng.next_float()));
        }
        if (trial % 7 == 0) w[size_t(n - 1)] = 0.0;
        if (std::all_of(w.begin(), w.end(), [](double x) { return x == 0.0; })) w[0] = 1.0;
        const Distribution1D d(w);
        const std::vector<double> cdf = distribution_cdf(w);
        for (float u0 : border_numbers(cdf, rng, 200, {0.f, 0.99999994f})) {
            const double uu = u0;
            const int want = binary_search_bin(cdf, d, uu);
            const double width = cdf[size_t(want) + 1] - cdf[size_t(want)];
            const float want_u =
                width > 0 ? float(std::clamp((uu - cdf[size_t(want)]) / width, 0.0, 0.99999994)) : 0.f;
            float u = u0;
            ASSERT_EQ(d.sample(u), want) << "n " << n << " u " << u0;
            ASSERT_EQ(u, want_u) << "n " << n << " u " << u0;
        }
    }
}

TEST(Envmap, PdfIntegratesToOneAndMatchesSampler) {
    const int W = 12, H = 7;
    std::vector<float> data(W * H * 3);
    for (int j = 0; j < H; ++j)
        for (int i = 0; i < W; ++i)
            for (int c = 0; c < 3; ++c) data[(j * W + i) * 3 + c] = (i == 2 && j == 3) ? 20.f : 0.1f + 0.05f * (i + j + c);
    EnvmapDesc d;
    d.values.data = data.data();
    d.values.height = H;
    d.values.width = W;
    d.values.channels = 3;
    // A rotation about x by 30 degrees.
    float c = std::cos(0.5236f), s = std::sin(0.5236f);
    float R[9] = {1, 0, 0, 0, c, -s, 0, s, c};
    std::copy(R, R + 9, d.to_world);
    Envmap env;
    env.build(d);
    Rng rng(11, 4);
    Acc pdf_int, L_uniform, L_sampled;
    for (int i = 0; i < 400000; ++i) {
        Vec3f w = square_to_sphere(rng.next_float(), rng.next_float());
        pdf_int.add(env.pdf(w) * 4 * kPi);
        L_uniform.add(luminance(env.eval(w)) * 4 * kPi);
        Vec3f ws, value;
        float pdf;
        ASSERT_TRUE(env.sample(rng.next_float(), rng.next_float(), ws, pdf, false, &value));
        // The density is exact; near the poles its float round trip through the rotation loses
        // digits (1 / sin(theta)), so compare away from them. So does the value the sampler
        // gives (looked up at the sampled position, not the direction's), which is eval's.
        float sin_theta = std::sin(env.position(ws).y / float(env.rows) * kPi);
        if (sin_theta > 0.1f) {
            EXPECT_NEAR(env.pdf(ws), pdf, 2e-3f * pdf);
            const Vec3f looked_up = env.eval(ws);
            for (int k = 0; k < 3; ++k) ASSERT_NEAR(value[k], looked_up[k], 2e-3f * (looked_up[k] + 0.1f)) << i;
        }
        L_sampled.add(luminance(value) / pdf);
    }
    EXPECT_NEAR(pdf_int.mean(), 1.0, 5 * pdf_int.se());
    EXPECT_NEAR(L_uniform.mean(), L_sampled.mean(), 5 * std::hypot(L_uniform.se(), L_sampled.se()));
}

// An RGB lat-long map of height x width texels over `data` (which must outlive it), built.
Envmap lat_long(const std::vector<float>& data, int height, int width) {
    EnvmapDesc d;
    d.values.data = data.data();
    d.values.height = height;
    d.values.width = width;
    d.values.channels = 3;
    Envmap env;
    env.build(d);
    return env;
}

// The compensated distribution (Envmap::compensated, for light samples combined with the BSDF's
// in an image alone): its density integrates to one over the sphere, agrees with its sampler's,
// is zero wherever the map is no brighter than its mean (all the light samples land on the
// bright patch), and the map's light above its mean, max(L - mean, 0), is estimated without
// bias by its samples. A constant map has none (empty), nor has a uniform lat-long map (its
// cells differ from their mean by rounding alone).
TEST(Envmap, CompensatedDistributionSamplesTheLightAboveTheMean) {
    const int W = 12, H = 7;
    std::vector<float> data(W * H * 3);
    for (int j = 0; j < H; ++j)
        for (int i = 0; i < W; ++i)
            for (int c = 0; c < 3; ++c) data[(j * W + i) * 3 + c] = (i == 2 && j == 3) ? 20.f : 0.1f + 0.01f * (i + c);
    const Envmap env = lat_long(data, H, W);
    ASSERT_TRUE(env.compensated().valid());
    // The mean over the sphere, from the cells' luminance as the distributions see them.
    double sum = 0, solid = 0;
    env.for_each_cell([&](int, int, double l, double sin_theta) {
        sum += l * sin_theta;
        solid += sin_theta;
    });
    const double mean = sum / solid;
    int above = 0;
    env.for_each_cell([&](int r, int c, double l, double) {
        const float pmf = env.compensated().pmf(r, c);
        if (l > mean * (1 + 1e-6)) {
            ++above;
            EXPECT_GT(pmf, 0.f) << r << "," << c;
        } else {
            EXPECT_EQ(pmf, 0.f) << r << "," << c;
        }
    });
    EXPECT_GT(above, 0);
    EXPECT_LT(above, 8);  // the cells touching the bright texel
    Rng rng(3, 9);
    Acc pdf_int, excess_uniform, excess_sampled;
    for (int i = 0; i < 400000; ++i) {
        const Vec3f w = square_to_sphere(rng.next_float(), rng.next_float());
        float pdf_w;
        env.eval(w, pdf_w, true);
        pdf_int.add(pdf_w * 4 * kPi);
        Vec3f ws;
        float pdf;
        ASSERT_TRUE(env.sample(rng.next_float(), rng.next_float(), ws, pdf, true));
        float pdf_back;
        env.eval(ws, pdf_back, true);
        const float sin_theta = std::sin(env.position(ws).y / float(env.rows) * kPi);
        if (sin_theta > 0.1f) {
            EXPECT_NEAR(pdf_back, pdf, 2e-3f * pdf);
        }
        // The cells' excess over the mean, as a function of direction: piecewise constant.
        auto excess = [&](const Vec3f& dir) {
            const Vec2f p = env.position(dir);
            const int r = std::min(int(p.y), env.rows - 1), c = std::min(int(p.x), env.cols - 1);
            double out = 0;
            env.for_each_cell([&](int rr, int cc, double l, double) {
                if (rr == r && cc == c) out = std::max(0.0, l - mean);
            });
            return out;
        };
        if (i % 50 == 0) {  // the excess is looked up by a scan of the cells: every 50th sample
            excess_uniform.add(excess(w) * 4 * kPi);
            excess_sampled.add(excess(ws) / pdf);
        }
    }
    EXPECT_NEAR(pdf_int.mean(), 1.0, 5 * pdf_int.se());
    EXPECT_NEAR(excess_uniform.mean(), excess_sampled.mean(), 5 * std::hypot(excess_uniform.se(), excess_sampled.se()));

    const std::vector<float> texel = {0.2f, 0.25f, 0.3f};
    const Envmap constant = lat_long(texel, 1, 1);
    EXPECT_TRUE(constant.dist.valid());
    EXPECT_FALSE(constant.compensated().valid());
    Vec3f ws;
    float pdf;
    EXPECT_FALSE(constant.sample(0.3f, 0.6f, ws, pdf, true));
    constant.eval(Vec3f(0, 1, 0), pdf, true);
    EXPECT_EQ(pdf, 0.f);
    const std::vector<float> grey(5 * 9 * 3, 0.2f);
    const Envmap uniform = lat_long(grey, 5, 9);
    EXPECT_TRUE(uniform.dist.valid());
    EXPECT_FALSE(uniform.compensated().valid());
}

TEST(Envmap, MitsubaLookupConvention) {
    // Texel column i sits at u = (i + 0.5) / W, row j at v = j / (H - 1); -z is u = 0, +y is
    // row 0; u wraps between the last column and the first.
    const int W = 8, H = 5;
    std::vector<float> data(W * H * 3, 0.f);
    for (int j = 0; j < H; ++j)
        for (int i = 0; i < W; ++i) data[(j * W + i) * 3] = float(100 * j + i);
    const Envmap env = lat_long(data, H, W);
    auto dir = [](double u, double v) {  // the local direction of (u, v)
        double phi = 2 * M_PI * u, theta = M_PI * v;
        return Vec3f(float(std::sin(theta) * std::sin(phi)), float(std::cos(theta)),
                     float(-std::sin(theta) * std::cos(phi)));
    };
    EXPECT_NEAR(env.eval(dir(0.5 / W, 0.5)).x, 200.f, 1e-3f);   // equator, column 0
    EXPECT_NEAR(env.eval(dir(4.5 / W, 0.5)).x, 204.f, 1e-3f);   // column 4
    EXPECT_NEAR(env.eval(dir(2.5 / W, 0.25)).x, 102.f, 1e-3f);  // row 1, column 2
    EXPECT_NEAR(env.eval(Vec3f(0, 0, -1)).x, 203.5f, 1e-3f);     // u = 0: half column 7, half column 0
    EXPECT_NEAR(env.eval(Vec3f(0, 0, 1)).x, 203.5f, 1e-3f);      // u = 0.5: columns 3 and 4
    EXPECT_NEAR(env.eval(dir(6.5 / W, 1e-6)).x, 6.f, 1e-2f);     // row 0
    EXPECT_NEAR(env.eval(dir(6.5 / W, 1 - 1e-6)).x, 406.f, 1e-2f);  // last row
}

// A constant (1x1) map, looked up without the direction's longitude: its value is its texel
// times the scale in every direction, within rounding of the bilinear lookup of the texel
// against itself, and its density is the general lookup's bit for bit (it depends on the
// latitude alone), with and without the value, rotated; its samples' value and density agree.
TEST(Envmap, ConstantMapLookup) {
    const float texel[3] = {0.2f, 0.25f, 0.3f};
    EnvmapDesc d;
    d.values.data = texel;
    d.values.height = d.values.width = 1;
    d.values.channels = 3;
    d.scale = 1.7f;
    const float c = std::cos(0.4f), s = std::sin(0.4f);
    const float R[9] = {c, 0, s, 0, 1, 0, -s, 0, c};
    std::copy(R, R + 9, d.to_world);
    Envmap env;
    env.build(d);
    ASSERT_TRUE(env.constant());
    const Vec3f value = Vec3f::load(texel) * d.scale;
    Rng rng(3, 9);
    Acc cosine, z2;
    for (int i = 0; i < 20000; ++i) {
        const Vec3f w = square_to_sphere(rng.next_float(), rng.next_float());
        const Vec3f L = env.eval(w);
        float pdf = -1.f;
        const Vec3f L2 = env.eval(w, pdf);
        for (int k = 0; k < 3; ++k) {
            EXPECT_EQ(L[k], value[k]);
            EXPECT_EQ(L2[k], value[k]);
            // The general lookup: the same texel, weights adding up to 1 up to rounding.
            EXPECT_NEAR(env.eval_at(env.position(w))[k], value[k], 2e-7f * value[k]);
        }
        // Sampled uniformly over the sphere: one density everywhere, and the sampler's.
        EXPECT_EQ(pdf, 0.25f * kInvPi);
        EXPECT_EQ(env.pdf(w), pdf);
        Vec3f ws;
        float spdf = -1.f;
        ASSERT_TRUE(env.sample(rng.next_float(), rng.next_float(), ws, spdf));
        EXPECT_EQ(spdf, pdf);
        EXPECT_EQ(env.eval(ws).x, value.x);
        EXPECT_NEAR(length(ws), 1.f, 1e-6f);
        // The integral of a clamped cosine about an arbitrary axis (pi), and of z^2 (4 pi / 3).
        const Vec3f n = normalize(Vec3f(0.3f, -0.5f, 0.8f));
        cosine.add(std::max(0.f, dot(n, ws)) / spdf);
        z2.add(ws.z * ws.z / spdf);
    }
    EXPECT_NEAR(cosine.mean(), kPi, 5 * cosine.se());
    EXPECT_NEAR(z2.mean(), 4 * kPi / 3, 5 * z2.se());
    // A black constant map is not sampled.
    const float black[3] = {0.f, 0.f, 0.f};
    d.values.data = black;
    Envmap dark;
    dark.build(d);
    Vec3f w;
    float p;
    EXPECT_FALSE(dark.sample(0.3f, 0.6f, w, p));
    EXPECT_EQ(dark.pdf(Vec3f(0.f, 1.f, 0.f)), 0.f);
}

TEST(Envmap, FootprintDerivativeMatchesFiniteDifferences) {
    const int W = 7, H = 6;
    std::vector<float> data(W * H * 3);
    Rng rng(3, 1);
    for (float& x : data) x = rng.next_float();
    EnvmapDesc d;
    d.values.data = data.data();
    d.values.height = H;
    d.values.width = W;
    d.values.channels = 3;
    const float a = 0.4f;  // a rotation about y
    const float R[9] = {std::cos(a), 0, std::sin(a), 0, 1, 0, -std::sin(a), 0, std::cos(a)};
    std::copy(R, R + 9, d.to_world);
    Envmap env;
    env.build(d);
    for (int trial = 0; trial < 50; ++trial) {
        Vec3f w(2 * rng.next_float() - 1, 2 * rng.next_float() - 1, 2 * rng.next_float() - 1);
        if (length(w) < 0.2f || std::abs(normalize(w).y) > 0.9f) continue;  // away from the poles
        w = normalize(w);
        Envmap::Footprint f = env.footprint(w);
        Vec3f dl(0.f);  // d(red) / d(local direction)
        for (int k = 0; k < 4; ++k) dl += f.dweight[k] * data[f.texel[k] * 3];
        Vec3f local = env.to_local(w);
        for (int i = 0; i < 3; ++i) {
            const float h = 1e-3f;
            Vec3f lp = local, lm = local;
            lp[i] += h;
            lm[i] -= h;
            float fd = (env.eval(env.to_world_dir(lp)).x - env.eval(env.to_world_dir(lm)).x) / (2 * h);
            EXPECT_NEAR(dl[i], fd, 2e-2f * (1.f + std::abs(fd))) << "trial " << trial << " component " << i;
        }
    }
}

// Solid angle of the spherical triangle with corners towards u, v, w from the origin (the
// closed form of Van Oosterom and Strackee, written out here again as the reference).
double solid_angle_of(const Vec3d& u, const Vec3d& v, const Vec3d& w) {
    const Vec3d a = normalize(u), b = normalize(v), c = normalize(w);
    return 2.0 * std::atan2(std::abs(dot(a, cross(b, c))), 1.0 + dot(a, b) + dot(b, c) + dot(c, a));
}

// Spherical triangle sampling: the solid angle against a brute-force count of uniform sphere
// directions; every sample in the triangle; the samples spread over its four midpoint
// sub-triangles in proportion to their closed-form solid angles (a histogram, chi-square);
// their mean direction equal to the closed-form first moment (1/omega) (1/2) sum theta_i n_i
// over the edges (arc length theta_i, unit normal n_i of the edge's plane).
TEST(SphericalTriangle, UniformInSolidAngle) {
    struct Case { Vec3d p, v0, v1, v2; };
    const Case cases[] = {
        {Vec3d(0, 0, 0), Vec3d(-1, 1, -1), Vec3d(1, 1, -1), Vec3d(0, 1, 1)},         // about 1.5 sr
        {Vec3d(0.1, 0.05, 0), Vec3d(-1, 0.1, -1), Vec3d(1, 0.1, -1), Vec3d(1, 0.1, 1)},  // nearly a hemisphere
        {Vec3d(0, 0, 0), Vec3d(3, 0.2, 0.1), Vec3d(3.5, 0.9, -0.4), Vec3d(2.5, 0.1, 0.5)},  // small, oblique
        {Vec3d(0.3, -0.2, 0.4), Vec3d(0, 2, 0), Vec3d(0.2, 2, 0), Vec3d(-5, 0.01, 0.3)},   // a sliver
    };
    for (int ci = 0; ci < 4; ++ci) {
        const Case& k = cases[ci];
        const SphericalTriangle st(k.p, k.v0, k.v1, k.v2);
        ASSERT_TRUE(st.usable()) << "case " << ci;
        const Vec3d A = k.v0 - k.p, B = k.v1 - k.p, C = k.v2 - k.p;
        EXPECT_NEAR(st.solid_angle, solid_angle_of(A, B, C), 1e-12) << "case " << ci;
        // The count: the fraction of uniform directions through the triangle is omega / 4 pi.
        Rng rng = Rng::for_sample(5, uint64_t(ci), 0);
        long inside = 0;
        const long M = 400000;
        for (long s = 0; s < M; ++s) {
            const Vec3f w = square_to_sphere(rng.next_float(), rng.next_float());
            TriangleHit<double> h;
            if (intersect_triangle(k.p, Vec3d(w), k.v0, k.v1, k.v2, h) && h.t > 0 && h.b1 >= 0 &&
                h.b2 >= 0 && h.b1 + h.b2 <= 1)
                ++inside;
        }
        const double frac = st.solid_angle / (4 * M_PI);
        EXPECT_NEAR(double(inside) / M, frac, 5 * std::sqrt(frac * (1 - frac) / M)) << "case " << ci;

        // Midpoint sub-triangles (corners 0, 1, 2 and the middle): their solid angles.
        const Vec3d m01 = 0.5 * (A + B), m12 = 0.5 * (B + C), m20 = 0.5 * (C + A);
        const double sub[4] = {solid_angle_of(A, m01, m20), solid_angle_of(B, m12, m01),
                               solid_angle_of(C, m20, m12), solid_angle_of(m01, m12, m20)};
        EXPECT_NEAR(sub[0] + sub[1] + sub[2] + sub[3], st.solid_angle, 1e-9 * st.solid_angle);
        // The first moment: (1/2) sum over edges of arc length times the edge plane's normal,
        // oriented with the corners' winding.
        const Vec3d a = normalize(A), b = normalize(B), c = normalize(C);
        const double sign = dot(a, cross(b, c)) > 0 ? 1.0 : -1.0;
        Vec3d moment(0.0);
        const Vec3d corners[3] = {a, b, c};
        for (int e = 0; e < 3; ++e) {
            const Vec3d& x = corners[e];
            const Vec3d& y = corners[(e + 1) % 3];
            const Vec3d n = cross(x, y);
            const double theta = std::atan2(length(n), dot(x, y));
            moment += (0.5 * sign * theta / length(n)) * n;
        }
        const Vec3d mean_expected = moment / st.solid_angle;

        const long N = 200000;
        long count[4] = {0, 0, 0, 0};
        Acc mean[3];
        long outside = 0;
        for (long s = 0; s < N; ++s) {
            const Vec3d w = st.sample(rng.next_float(), rng.next_float());
            ASSERT_NEAR(length(w), 1.0, 1e-12);
            TriangleHit<double> h;
            const bool hit = intersect_triangle(k.p, w, k.v0, k.v1, k.v2, h) && h.t > 0;
            const double b1 = h.b1, b2 = h.b2, b0 = 1 - b1 - b2;
            if (!hit || b1 < -1e-9 || b2 < -1e-9 || b0 < -1e-9) {
                ++outside;
                continue;
            }
            ++count[b0 > 0.5 ? 0 : b1 > 0.5 ? 1 : b2 > 0.5 ? 2 : 3];
            mean[0].add(w.x);
            mean[1].add(w.y);
            mean[2].add(w.z);
        }
        EXPECT_EQ(outside, 0) << "case " << ci;
        double chi2 = 0;
        for (int j = 0; j < 4; ++j) {
            const double expected = N * sub[j] / st.solid_angle;
            chi2 += (count[j] - expected) * (count[j] - expected) / expected;
        }
        // 3 degrees of freedom: P(chi2 > 16.3) = 0.001.
        EXPECT_LT(chi2, 16.3) << "case " << ci << ": " << count[0] << " " << count[1] << " " << count[2] << " " << count[3];
        for (int j = 0; j < 3; ++j)
            EXPECT_NEAR(mean[j].mean(), mean_expected[j], 5 * mean[j].se() + 1e-9)
                << "case " << ci << " axis " << j;
    }
    // Left to area sampling: p in the triangle's plane, a far triangle (below the bound),
    // and a corner at p.
    EXPECT_FALSE(SphericalTriangle(Vec3d(5, 0, 0), Vec3d(0, 0, 0), Vec3d(1, 0, 0), Vec3d(0, 1, 0)).usable());
    EXPECT_FALSE(SphericalTriangle(Vec3d(0, 0, 100), Vec3d(0, 0, 0), Vec3d(1, 0, 0), Vec3d(0, 1, 0)).usable());
    EXPECT_FALSE(SphericalTriangle(Vec3d(0, 0, 0), Vec3d(0, 0, 0), Vec3d(1, 0, 0), Vec3d(0, 1, 1)).usable());
}

TEST(Filter, GaussianSamplerMatchesWeights) {
    PixelFilter f;
    f.build(FilterType::Gaussian, 0.5f);
    EXPECT_FLOAT_EQ(f.radius(), 2.f);
    const int bins = 16;
    std::vector<double> hist(bins, 0);
    Rng rng(5, 5);
    const int N = 400000;
    for (int i = 0; i < N; ++i) {
        float x = f.sample(rng.next_float());
        ASSERT_LE(std::abs(x), 2.f);
        hist[std::min(bins - 1, int((x + 2.f) / 4.f * bins))] += 1;
    }
    for (int b = 0; b < bins; ++b) {
        // Expected mass of the bin from the normalised weight (midpoint rule, fine steps).
        double m = 0;
        for (int k = 0; k < 100; ++k) {
            double x = -2.0 + (b + (k + 0.5) / 100.0) * 4.0 / bins;
            m += f.eval(float(x)) * 4.0 / bins / 100.0;
        }
        EXPECT_NEAR(hist[b] / N, m, 5 * std::sqrt(m / N) + 1e-4) << "bin " << b;
    }
}

}  // namespace
}  // namespace edgepath
