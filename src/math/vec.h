// Small fixed-size vectors. Templated on the scalar so the same code runs in float (rendering)
// and double (finite-difference tests, edge functions).
#pragma once
#include <algorithm>
#include <cmath>

namespace edgepath {

template <class T>
struct TVec2 {
    T x = T(0), y = T(0);
    TVec2() = default;
    TVec2(T x_, T y_) : x(x_), y(y_) {}
    T operator[](int i) const { return i == 0 ? x : y; }
    T& operator[](int i) { return i == 0 ? x : y; }
};

template <class T>
struct TVec3 {
    T x = T(0), y = T(0), z = T(0);
    TVec3() = default;
    TVec3(T x_, T y_, T z_) : x(x_), y(y_), z(z_) {}
    explicit TVec3(T s) : x(s), y(s), z(s) {}
    template <class U>
    explicit TVec3(const TVec3<U>& o) : x(T(o.x)), y(T(o.y)), z(T(o.z)) {}
    static TVec3 load(const float* p) { return TVec3(T(p[0]), T(p[1]), T(p[2])); }
    T operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
    T& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }
    TVec3& operator+=(const TVec3& o) { x += o.x; y += o.y; z += o.z; return *this; }
    TVec3& operator-=(const TVec3& o) { x -= o.x; y -= o.y; z -= o.z; return *this; }
    TVec3& operator*=(const TVec3& o) { x *= o.x; y *= o.y; z *= o.z; return *this; }
    TVec3& operator*=(T s) { x *= s; y *= s; z *= s; return *this; }
    TVec3& operator/=(T s) { T r = T(1) / s; x *= r; y *= r; z *= r; return *this; }
};

using Vec2f = TVec2<float>;
using Vec3f = TVec3<float>;
using Vec2d = TVec2<double>;
using Vec3d = TVec3<double>;

template <class T> inline TVec3<T> operator+(TVec3<T> a, const TVec3<T>& b) { return a += b; }
template <class T> inline TVec3<T> operator-(TVec3<T> a, const TVec3<T>& b) { return a -= b; }
template <class T> inline TVec3<T> operator*(TVec3<T> a, const TVec3<T>& b) { return a *= b; }
template <class T> inline TVec3<T> operator*(TVec3<T> a, T s) { return a *= s; }
template <class T> inline TVec3<T> operator*(T s, TVec3<T> a) { return a *= s; }
template <class T> inline TVec3<T> operator/(TVec3<T> a, T s) { return a /= s; }
template <class T> inline TVec3<T> operator/(const TVec3<T>& a, const TVec3<T>& b) {
    return {a.x / b.x, a.y / b.y, a.z / b.z};
}
template <class T> inline TVec3<T> operator-(const TVec3<T>& a) { return {-a.x, -a.y, -a.z}; }

template <class T> inline T dot(const TVec3<T>& a, const TVec3<T>& b) {
    return a.x * b.x + a.y * b.y + a.z * b.z;
}
template <class T> inline TVec3<T> cross(const TVec3<T>& a, const TVec3<T>& b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
template <class T> inline T length_squared(const TVec3<T>& a) { return dot(a, a); }
template <class T> inline T length(const TVec3<T>& a) { return std::sqrt(dot(a, a)); }
template <class T> inline TVec3<T> normalize(const TVec3<T>& a) {
    T l = length(a);
    return l > T(0) ? a / l : a;
}
template <class T> inline T max_component(const TVec3<T>& a) { return std::max(a.x, std::max(a.y, a.z)); }
template <class T> inline TVec3<T> min(const TVec3<T>& a, const TVec3<T>& b) {
    return {std::min(a.x, b.x), std::min(a.y, b.y), std::min(a.z, b.z)};
}
template <class T> inline TVec3<T> max(const TVec3<T>& a, const TVec3<T>& b) {
    return {std::max(a.x, b.x), std::max(a.y, b.y), std::max(a.z, b.z)};
}
template <class T> inline T max_abs_component(const TVec3<T>& a) {
    return std::max(std::abs(a.x), std::max(std::abs(a.y), std::abs(a.z)));
}
template <class T> inline T luminance(const TVec3<T>& c) {
    return T(0.212671) * c.x + T(0.715160) * c.y + T(0.072169) * c.z;
}
template <class T> inline bool is_black(const TVec3<T>& c) { return c.x == 0 && c.y == 0 && c.z == 0; }
template <class T> inline bool all_finite(const TVec3<T>& c) {
    return std::isfinite(c.x) && std::isfinite(c.y) && std::isfinite(c.z);
}

}  // namespace edgepath
