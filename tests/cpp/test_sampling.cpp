// Building blocks of the forward renderer: densities integrate to one, samplers agree with their
// densities, estimators agree with direct integration.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "sampling/distribution.h"
#include "sampling/rng.h"
#include "sampling/warp.h"
#include "scene/bsdf.h"
#include "scene/envmap.h"
#include "scene/filter.h"

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
        // The cdf as build() computes it.
        std::vector<double> cdf(size_t(n) + 1, 0.0);
        for (int i = 0; i < n; ++i) cdf[size_t(i) + 1] = cdf[size_t(i)] + w[size_t(i)];
        const double total = cdf[size_t(n)];
        for (int i = 0; i < n; ++i) cdf[size_t(i) + 1] /= total;
        cdf[size_t(n)] = 1.0;
        std::vector<float> us;
        for (int k = 0; k < 2000; ++k) us.push_back(rng.next_float());
        for (int i = 0; i <= n; ++i) {
            const float c = float(cdf[size_t(i)]);
            for (float u : {c, std::nextafter(c, 0.f), std::nextafter(c, 1.f)})
                if (u >= 0.f && u < 1.f) us.push_back(u);
        }
        for (float u0 : us) {
            const double uu = u0;
            int want = int(std::upper_bound(cdf.begin(), cdf.end(), uu) - cdf.begin()) - 1;
            want = std::clamp(want, 0, n - 1);
            while (d.pmf(want) == 0.f && want > 0) --want;
            float u = u0;
            ASSERT_EQ(d.sample(u), want) << "n " << n << " u " << u0;
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
        Vec3f ws;
        float pdf;
        ASSERT_TRUE(env.sample(rng.next_float(), rng.next_float(), ws, pdf));
        // The density is exact; near the poles its float round trip through the rotation loses
        // digits (1 / sin(theta)), so compare away from them.
        float sin_theta = std::sin(env.position(ws).y / float(env.rows) * kPi);
        if (sin_theta > 0.1f) {
            EXPECT_NEAR(env.pdf(ws), pdf, 2e-3f * pdf);
        }
        L_sampled.add(luminance(env.eval(ws)) / pdf);
    }
    EXPECT_NEAR(pdf_int.mean(), 1.0, 5 * pdf_int.se());
    EXPECT_NEAR(L_uniform.mean(), L_sampled.mean(), 5 * std::hypot(L_uniform.se(), L_sampled.se()));
}

TEST(Envmap, MitsubaLookupConvention) {
    // Texel column i sits at u = (i + 0.5) / W, row j at v = j / (H - 1); -z is u = 0, +y is
    // row 0; u wraps between the last column and the first.
    const int W = 8, H = 5;
    std::vector<float> data(W * H * 3, 0.f);
    for (int j = 0; j < H; ++j)
        for (int i = 0; i < W; ++i) data[(j * W + i) * 3] = float(100 * j + i);
    EnvmapDesc d;
    d.values.data = data.data();
    d.values.height = H;
    d.values.width = W;
    d.values.channels = 3;
    Envmap env;
    env.build(d);
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
