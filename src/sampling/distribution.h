// Piecewise-constant distributions in one and two dimensions.
#pragma once
#include <algorithm>
#include <cmath>
#include <vector>

namespace edgepath {

class Distribution1D {
public:
    Distribution1D() = default;
    explicit Distribution1D(std::vector<double> weights) { build(std::move(weights)); }

    void build(std::vector<double> weights) {
        n_ = int(weights.size());
        cdf_.assign(n_ + 1, 0.0);
        for (int i = 0; i < n_; ++i) cdf_[i + 1] = cdf_[i] + std::max(0.0, weights[i]);
        total_ = cdf_[n_];
        count_ = n_ <= 8 && std::isfinite(total_);
        pmf_.assign(n_, 0.f);
        if (total_ > 0)
            for (int i = 0; i < n_; ++i) {
                cdf_[i + 1] /= total_;
                pmf_[i] = float(std::max(0.0, weights[i]) / total_);
            }
        if (n_ > 0) cdf_[n_] = 1.0;
        // The guide table: for each of n equal slices of [0, 1), the last bin whose cdf is at
        // or below the slice's start (one pass, the cdf being monotone).
        guide_.assign(size_t(n_ > 0 ? n_ : 0), 0);
        for (int j = 0, i = 0; j < n_; ++j) {
            const double start = double(j) / double(n_);
            while (i + 1 < n_ && cdf_[i + 1] <= start) ++i;
            guide_[size_t(j)] = i;
        }
    }

    int size() const { return n_; }
    double total() const { return total_; }
    bool valid() const { return n_ > 0 && total_ > 0; }
    float pmf(int i) const { return pmf_[i]; }

    // Picks a bin; `u` in [0,1) becomes the position inside the bin, in [0,1).
    int sample(float& u) const {
        double uu = u;
        int i;
        if (uu >= 0.0 && uu < 1.0 && n_ > 0) {
            // The last bin with cdf <= u, as the binary search below finds it: from the guide
            // table's entry for u's slice, forwards (and backwards, where rounding put u's
            // slice a step beyond u).
            if (count_) {
                // A few bins (a light of a quad or two): the cdf being monotone and cdf_[0] = 0
                // <= u, that bin is the number of cdf_[1..n-1] at or below u, counted without
                // branches (a walk's data-dependent branches mispredict about once a call).
                i = 0;
                for (int k = 1; k < n_; ++k) i += int(cdf_[k] <= uu);
            } else {
                i = guide_[size_t(std::min(int(uu * double(n_)), n_ - 1))];
                while (i > 0 && cdf_[i] > uu) --i;
                while (i + 1 < n_ && cdf_[i + 1] <= uu) ++i;
            }
        } else {
            i = int(std::upper_bound(cdf_.begin(), cdf_.end(), uu) - cdf_.begin()) - 1;
            i = std::clamp(i, 0, n_ - 1);
        }
        while (pmf_[i] == 0.f && i > 0) --i;  // never land on an empty bin at a cdf plateau
        double width = cdf_[i + 1] - cdf_[i];
        u = width > 0 ? float(std::clamp((uu - cdf_[i]) / width, 0.0, 0.99999994)) : 0.f;
        return i;
    }

private:
    bool count_ = false;  // few bins and a finite cdf: sample() counts rather than walks
    int n_ = 0;
    double total_ = 0;
    std::vector<double> cdf_;
    std::vector<float> pmf_;
    std::vector<int> guide_;
};

// Rows by a marginal, then a column within the row. Density over the unit square is
// pmf(row, col) * rows * cols.
class Distribution2D {
public:
    Distribution2D() = default;
    // weights: rows x cols, row-major.
    void build(const std::vector<double>& weights, int rows, int cols) {
        rows_ = rows;
        cols_ = cols;
        conditional_.resize(rows);
        std::vector<double> marginal(rows);
        for (int r = 0; r < rows; ++r) {
            std::vector<double> row(weights.begin() + size_t(r) * cols, weights.begin() + size_t(r + 1) * cols);
            conditional_[r].build(row);
            marginal[r] = conditional_[r].total();
        }
        marginal_.build(marginal);
    }
    bool valid() const { return marginal_.valid(); }
    int rows() const { return rows_; }
    int cols() const { return cols_; }

    // Returns (row, col); u1/u2 become positions inside the cell.
    void sample(float& u_row, float& u_col, int& row, int& col) const {
        row = marginal_.sample(u_row);
        col = conditional_[row].sample(u_col);
    }
    float pmf(int row, int col) const { return marginal_.pmf(row) * conditional_[row].pmf(col); }

private:
    int rows_ = 0, cols_ = 0;
    Distribution1D marginal_;
    std::vector<Distribution1D> conditional_;
};

}  // namespace edgepath
