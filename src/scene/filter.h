// Pixel filters, importance-sampled: every camera sample belongs to one pixel and carries weight
// one, the film point drawn from the filter around the pixel centre. The expected pixel value is
// the filter-weighted mean of radiance (what a splatting film normalised by summed weights gives).
// Box: one pixel wide. Gaussian: separable, stddev s, cut at 4 s and lowered by its value there
// (Mitsuba's `gaussian`). Tent: separable, 1 - |x| / r within radius r (Mitsuba's `tent`).
#pragma once
#include <cmath>
#include <vector>
#include "sampling/distribution.h"
#include "scene/desc.h"

namespace edgepath {

class PixelFilter {
public:
    void build(FilterType type, float stddev, float tent_radius = 1.f) {
        type_ = type;
        if (type == FilterType::Box) {
            radius_ = 0.5f;
            return;
        }
        stddev_ = stddev;
        radius_ = type == FilterType::Tent ? tent_radius : 4.f * stddev;
        std::vector<double> w(kBins);
        norm_ = 0.0;
        for (int i = 0; i < kBins; ++i) {
            double x = (-1.0 + 2.0 * (i + 0.5) / kBins) * radius_;
            w[i] = raw(x);
            norm_ += w[i] * 2.0 * radius_ / kBins;
        }
        table_.build(w);
    }

    float radius() const { return radius_; }

    // Offset from the pixel centre along one axis, in pixels.
    float sample(float u) const {
        if (type_ == FilterType::Box) return u - 0.5f;
        int i = table_.sample(u);
        return float((-1.0 + 2.0 * (i + u) / kBins) * radius_);
    }

    // Normalised 1D weight at offset x (integrates to one); the 2D weight is the product.
    float eval(float x) const {
        // Box: half-open [-0.5, 0.5), like the film samples, so a point on the border of two
        // pixels belongs to one of them (the right / lower one).
        if (type_ == FilterType::Box) return x >= -0.5f && x < 0.5f ? 1.f : 0.f;
        return float(raw(x) / norm_);
    }

private:
    static constexpr int kBins = 4096;
    double raw(double x) const {
        if (std::abs(x) >= radius_) return 0.0;
        if (type_ == FilterType::Tent) return 1.0 - std::abs(x) / radius_;
        auto g = [&](double t) { return std::exp(-0.5 * t * t / (double(stddev_) * stddev_)); };
        return std::max(0.0, g(x) - g(radius_));
    }
    FilterType type_ = FilterType::Box;
    float stddev_ = 0.5f, radius_ = 0.5f;
    double norm_ = 1.0;
    Distribution1D table_;
};

}  // namespace edgepath
