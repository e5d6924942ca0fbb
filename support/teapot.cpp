#include "support/teapot.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace edgepath {

namespace {

// Newell's data set (z up): 306 control points and 32 patches of 4 x 4 indices (zero-based),
// row by row. Rows run from the top of a part downwards (or from a pole outwards, or along the
// handle and the spout); columns run around. With P(s, t) the patch at row parameter s and column
// parameter t, cross(dP/dt, dP/ds) points out of the teapot for every patch.
constexpr int kNumPatches = 32;
constexpr int kNumPoints = 306;

const int kPatches[kNumPatches][16] = {
    // rim
    {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15},
    {3, 16, 17, 18, 7, 19, 20, 21, 11, 22, 23, 24, 15, 25, 26, 27},
    {18, 28, 29, 30, 21, 31, 32, 33, 24, 34, 35, 36, 27, 37, 38, 39},
    {30, 40, 41, 0, 33, 42, 43, 4, 36, 44, 45, 8, 39, 46, 47, 12},
    // body, upper
    {12, 13, 14, 15, 48, 49, 50, 51, 52, 53, 54, 55, 56, 57, 58, 59},
    {15, 25, 26, 27, 51, 60, 61, 62, 55, 63, 64, 65, 59, 66, 67, 68},
    {27, 37, 38, 39, 62, 69, 70, 71, 65, 72, 73, 74, 68, 75, 76, 77},
    {39, 46, 47, 12, 71, 78, 79, 48, 74, 80, 81, 52, 77, 82, 83, 56},
    // body, lower
    {56, 57, 58, 59, 84, 85, 86, 87, 88, 89, 90, 91, 92, 93, 94, 95},
    {59, 66, 67, 68, 87, 96, 97, 98, 91, 99, 100, 101, 95, 102, 103, 104},
    {68, 75, 76, 77, 98, 105, 106, 107, 101, 108, 109, 110, 104, 111, 112, 113},
    {77, 82, 83, 56, 107, 114, 115, 84, 110, 116, 117, 88, 113, 118, 119, 92},
    // handle
    {120, 121, 122, 123, 124, 125, 126, 127, 128, 129, 130, 131, 132, 133, 134, 135},
    {123, 136, 137, 120, 127, 138, 139, 124, 131, 140, 141, 128, 135, 142, 143, 132},
    {132, 133, 134, 135, 144, 145, 146, 147, 148, 149, 150, 151, 68, 152, 153, 154},
    {135, 142, 143, 132, 147, 155, 156, 144, 151, 157, 158, 148, 154, 159, 160, 68},
    // spout
    {161, 162, 163, 164, 165, 166, 167, 168, 169, 170, 171, 172, 173, 174, 175, 176},
    {164, 177, 178, 161, 168, 179, 180, 165, 172, 181, 182, 169, 176, 183, 184, 173},
    {173, 174, 175, 176, 185, 186, 187, 188, 189, 190, 191, 192, 193, 194, 195, 196},
    {176, 183, 184, 173, 188, 197, 198, 185, 192, 199, 200, 189, 196, 201, 202, 193},
    // lid knob (pole at the top)
    {203, 203, 203, 203, 206, 207, 208, 209, 210, 210, 210, 210, 211, 212, 213, 214},
    {203, 203, 203, 203, 209, 216, 217, 218, 210, 210, 210, 210, 214, 219, 220, 221},
    {203, 203, 203, 203, 218, 223, 224, 225, 210, 210, 210, 210, 221, 226, 227, 228},
    {203, 203, 203, 203, 225, 229, 230, 206, 210, 210, 210, 210, 228, 231, 232, 211},
    // lid
    {211, 212, 213, 214, 233, 234, 235, 236, 237, 238, 239, 240, 241, 242, 243, 244},
    {214, 219, 220, 221, 236, 245, 246, 247, 240, 248, 249, 250, 244, 251, 252, 253},
    {221, 226, 227, 228, 247, 254, 255, 256, 250, 257, 258, 259, 253, 260, 261, 262},
    {228, 231, 232, 211, 256, 263, 264, 233, 259, 265, 266, 237, 262, 267, 268, 241},
    // bottom (pole at the centre)
    {269, 269, 269, 269, 278, 279, 280, 281, 274, 275, 276, 277, 270, 271, 272, 273},
    {269, 269, 269, 269, 281, 288, 289, 290, 277, 285, 286, 287, 273, 282, 283, 284},
    {269, 269, 269, 269, 290, 297, 298, 299, 287, 294, 295, 296, 284, 291, 292, 293},
    {269, 269, 269, 269, 299, 304, 305, 278, 296, 302, 303, 274, 293, 300, 301, 270},
};

const float kPoints[kNumPoints][3] = {
    // 0: rim
    {1.4f, 0.0f, 2.4f}, {1.4f, -0.784f, 2.4f}, {0.784f, -1.4f, 2.4f}, {0.0f, -1.4f, 2.4f},
    {1.3375f, 0.0f, 2.53125f}, {1.3375f, -0.749f, 2.53125f}, {0.749f, -1.3375f, 2.53125f}, {0.0f, -1.3375f, 2.53125f},
    {1.4375f, 0.0f, 2.53125f}, {1.4375f, -0.805f, 2.53125f}, {0.805f, -1.4375f, 2.53125f}, {0.0f, -1.4375f, 2.53125f},
    {1.5f, 0.0f, 2.4f}, {1.5f, -0.84f, 2.4f}, {0.84f, -1.5f, 2.4f}, {0.0f, -1.5f, 2.4f},
    // 16
    {-0.784f, -1.4f, 2.4f}, {-1.4f, -0.784f, 2.4f}, {-1.4f, 0.0f, 2.4f},
    {-0.749f, -1.3375f, 2.53125f}, {-1.3375f, -0.749f, 2.53125f}, {-1.3375f, 0.0f, 2.53125f},
    {-0.805f, -1.4375f, 2.53125f}, {-1.4375f, -0.805f, 2.53125f}, {-1.4375f, 0.0f, 2.53125f},
    {-0.84f, -1.5f, 2.4f}, {-1.5f, -0.84f, 2.4f}, {-1.5f, 0.0f, 2.4f},
    // 28
    {-1.4f, 0.784f, 2.4f}, {-0.784f, 1.4f, 2.4f}, {0.0f, 1.4f, 2.4f},
    {-1.3375f, 0.749f, 2.53125f}, {-0.749f, 1.3375f, 2.53125f}, {0.0f, 1.3375f, 2.53125f},
    {-1.4375f, 0.805f, 2.53125f}, {-0.805f, 1.4375f, 2.53125f}, {0.0f, 1.4375f, 2.53125f},
    {-1.5f, 0.84f, 2.4f}, {-0.84f, 1.5f, 2.4f}, {0.0f, 1.5f, 2.4f},
    // 40
    {0.784f, 1.4f, 2.4f}, {1.4f, 0.784f, 2.4f},
    {0.749f, 1.3375f, 2.53125f}, {1.3375f, 0.749f, 2.53125f},
    {0.805f, 1.4375f, 2.53125f}, {1.4375f, 0.805f, 2.53125f},
    {0.84f, 1.5f, 2.4f}, {1.5f, 0.84f, 2.4f},
    // 48: body
    {1.75f, 0.0f, 1.875f}, {1.75f, -0.98f, 1.875f}, {0.98f, -1.75f, 1.875f}, {0.0f, -1.75f, 1.875f},
    {2.0f, 0.0f, 1.35f}, {2.0f, -1.12f, 1.35f}, {1.12f, -2.0f, 1.35f}, {0.0f, -2.0f, 1.35f},
    {2.0f, 0.0f, 0.9f}, {2.0f, -1.12f, 0.9f}, {1.12f, -2.0f, 0.9f}, {0.0f, -2.0f, 0.9f},
    // 60
    {-0.98f, -1.75f, 1.875f}, {-1.75f, -0.98f, 1.875f}, {-1.75f, 0.0f, 1.875f},
    {-1.12f, -2.0f, 1.35f}, {-2.0f, -1.12f, 1.35f}, {-2.0f, 0.0f, 1.35f},
    {-1.12f, -2.0f, 0.9f}, {-2.0f, -1.12f, 0.9f}, {-2.0f, 0.0f, 0.9f},
    // 69
    {-1.75f, 0.98f, 1.875f}, {-0.98f, 1.75f, 1.875f}, {0.0f, 1.75f, 1.875f},
    {-2.0f, 1.12f, 1.35f}, {-1.12f, 2.0f, 1.35f}, {0.0f, 2.0f, 1.35f},
    {-2.0f, 1.12f, 0.9f}, {-1.12f, 2.0f, 0.9f}, {0.0f, 2.0f, 0.9f},
    // 78
    {0.98f, 1.75f, 1.875f}, {1.75f, 0.98f, 1.875f},
    {1.12f, 2.0f, 1.35f}, {2.0f, 1.12f, 1.35f},
    {1.12f, 2.0f, 0.9f}, {2.0f, 1.12f, 0.9f},
    // 84
    {2.0f, 0.0f, 0.45f}, {2.0f, -1.12f, 0.45f}, {1.12f, -2.0f, 0.45f}, {0.0f, -2.0f, 0.45f},
    {1.5f, 0.0f, 0.225f}, {1.5f, -0.84f, 0.225f}, {0.84f, -1.5f, 0.225f}, {0.0f, -1.5f, 0.225f},
    {1.5f, 0.0f, 0.15f}, {1.5f, -0.84f, 0.15f}, {0.84f, -1.5f, 0.15f}, {0.0f, -1.5f, 0.15f},
    // 96
    {-1.12f, -2.0f, 0.45f}, {-2.0f, -1.12f, 0.45f}, {-2.0f, 0.0f, 0.45f},
    {-0.84f, -1.5f, 0.225f}, {-1.5f, -0.84f, 0.225f}, {-1.5f, 0.0f, 0.225f},
    {-0.84f, -1.5f, 0.15f}, {-1.5f, -0.84f, 0.15f}, {-1.5f, 0.0f, 0.15f},
    // 105
    {-2.0f, 1.12f, 0.45f}, {-1.12f, 2.0f, 0.45f}, {0.0f, 2.0f, 0.45f},
    {-1.5f, 0.84f, 0.225f}, {-0.84f, 1.5f, 0.225f}, {0.0f, 1.5f, 0.225f},
    {-1.5f, 0.84f, 0.15f}, {-0.84f, 1.5f, 0.15f}, {0.0f, 1.5f, 0.15f},
    // 114
    {1.12f, 2.0f, 0.45f}, {2.0f, 1.12f, 0.45f},
    {0.84f, 1.5f, 0.225f}, {1.5f, 0.84f, 0.225f},
    {0.84f, 1.5f, 0.15f}, {1.5f, 0.84f, 0.15f},
    // 120: handle
    {-1.6f, 0.0f, 2.025f}, {-1.6f, -0.3f, 2.025f}, {-1.5f, -0.3f, 2.25f}, {-1.5f, 0.0f, 2.25f},
    {-2.3f, 0.0f, 2.025f}, {-2.3f, -0.3f, 2.025f}, {-2.5f, -0.3f, 2.25f}, {-2.5f, 0.0f, 2.25f},
    {-2.7f, 0.0f, 2.025f}, {-2.7f, -0.3f, 2.025f}, {-3.0f, -0.3f, 2.25f}, {-3.0f, 0.0f, 2.25f},
    {-2.7f, 0.0f, 1.8f}, {-2.7f, -0.3f, 1.8f}, {-3.0f, -0.3f, 1.8f}, {-3.0f, 0.0f, 1.8f},
    // 136
    {-1.5f, 0.3f, 2.25f}, {-1.6f, 0.3f, 2.025f},
    {-2.5f, 0.3f, 2.25f}, {-2.3f, 0.3f, 2.025f},
    {-3.0f, 0.3f, 2.25f}, {-2.7f, 0.3f, 2.025f},
    {-3.0f, 0.3f, 1.8f}, {-2.7f, 0.3f, 1.8f},
    // 144
    {-2.7f, 0.0f, 1.575f}, {-2.7f, -0.3f, 1.575f}, {-3.0f, -0.3f, 1.35f}, {-3.0f, 0.0f, 1.35f},
    {-2.5f, 0.0f, 1.125f}, {-2.5f, -0.3f, 1.125f}, {-2.65f, -0.3f, 0.9375f}, {-2.65f, 0.0f, 0.9375f},
    {-2.0f, -0.3f, 0.9f}, {-1.9f, -0.3f, 0.6f}, {-1.9f, 0.0f, 0.6f},
    // 155
    {-3.0f, 0.3f, 1.35f}, {-2.7f, 0.3f, 1.575f},
    {-2.65f, 0.3f, 0.9375f}, {-2.5f, 0.3f, 1.125f},
    {-1.9f, 0.3f, 0.6f}, {-2.0f, 0.3f, 0.9f},
    // 161: spout
    {1.7f, 0.0f, 1.425f}, {1.7f, -0.66f, 1.425f}, {1.7f, -0.66f, 0.6f}, {1.7f, 0.0f, 0.6f},
    {2.6f, 0.0f, 1.425f}, {2.6f, -0.66f, 1.425f}, {3.1f, -0.66f, 0.825f}, {3.1f, 0.0f, 0.825f},
    {2.3f, 0.0f, 2.1f}, {2.3f, -0.25f, 2.1f}, {2.4f, -0.25f, 2.025f}, {2.4f, 0.0f, 2.025f},
    {2.7f, 0.0f, 2.4f}, {2.7f, -0.25f, 2.4f}, {3.3f, -0.25f, 2.4f}, {3.3f, 0.0f, 2.4f},
    // 177
    {1.7f, 0.66f, 0.6f}, {1.7f, 0.66f, 1.425f},
    {3.1f, 0.66f, 0.825f}, {2.6f, 0.66f, 1.425f},
    {2.4f, 0.25f, 2.025f}, {2.3f, 0.25f, 2.1f},
    {3.3f, 0.25f, 2.4f}, {2.7f, 0.25f, 2.4f},
    // 185
    {2.8f, 0.0f, 2.475f}, {2.8f, -0.25f, 2.475f}, {3.525f, -0.25f, 2.49375f}, {3.525f, 0.0f, 2.49375f},
    {2.9f, 0.0f, 2.475f}, {2.9f, -0.15f, 2.475f}, {3.45f, -0.15f, 2.5125f}, {3.45f, 0.0f, 2.5125f},
    {2.8f, 0.0f, 2.4f}, {2.8f, -0.15f, 2.4f}, {3.2f, -0.15f, 2.4f}, {3.2f, 0.0f, 2.4f},
    // 197
    {3.525f, 0.25f, 2.49375f}, {2.8f, 0.25f, 2.475f},
    {3.45f, 0.15f, 2.5125f}, {2.9f, 0.15f, 2.475f},
    {3.2f, 0.15f, 2.4f}, {2.8f, 0.15f, 2.4f},
    // 203: lid knob (204, 205, 215 and 222 are unused in this version of the data)
    {0.0f, 0.0f, 3.15f}, {0.0f, -0.002f, 3.15f}, {0.002f, 0.0f, 3.15f},
    {0.8f, 0.0f, 3.15f}, {0.8f, -0.45f, 3.15f}, {0.45f, -0.8f, 3.15f}, {0.0f, -0.8f, 3.15f},
    {0.0f, 0.0f, 2.85f},
    {0.2f, 0.0f, 2.7f}, {0.2f, -0.112f, 2.7f}, {0.112f, -0.2f, 2.7f}, {0.0f, -0.2f, 2.7f},
    // 215
    {-0.002f, 0.0f, 3.15f}, {-0.45f, -0.8f, 3.15f}, {-0.8f, -0.45f, 3.15f}, {-0.8f, 0.0f, 3.15f},
    {-0.112f, -0.2f, 2.7f}, {-0.2f, -0.112f, 2.7f}, {-0.2f, 0.0f, 2.7f},
    // 222
    {0.0f, 0.002f, 3.15f}, {-0.8f, 0.45f, 3.15f}, {-0.45f, 0.8f, 3.15f}, {0.0f, 0.8f, 3.15f},
    {-0.2f, 0.112f, 2.7f}, {-0.112f, 0.2f, 2.7f}, {0.0f, 0.2f, 2.7f},
    // 229
    {0.45f, 0.8f, 3.15f}, {0.8f, 0.45f, 3.15f},
    {0.112f, 0.2f, 2.7f}, {0.2f, 0.112f, 2.7f},
    // 233: lid
    {0.4f, 0.0f, 2.55f}, {0.4f, -0.224f, 2.55f}, {0.224f, -0.4f, 2.55f}, {0.0f, -0.4f, 2.55f},
    {1.3f, 0.0f, 2.55f}, {1.3f, -0.728f, 2.55f}, {0.728f, -1.3f, 2.55f}, {0.0f, -1.3f, 2.55f},
    {1.3f, 0.0f, 2.4f}, {1.3f, -0.728f, 2.4f}, {0.728f, -1.3f, 2.4f}, {0.0f, -1.3f, 2.4f},
    // 245
    {-0.224f, -0.4f, 2.55f}, {-0.4f, -0.224f, 2.55f}, {-0.4f, 0.0f, 2.55f},
    {-0.728f, -1.3f, 2.55f}, {-1.3f, -0.728f, 2.55f}, {-1.3f, 0.0f, 2.55f},
    {-0.728f, -1.3f, 2.4f}, {-1.3f, -0.728f, 2.4f}, {-1.3f, 0.0f, 2.4f},
    // 254
    {-0.4f, 0.224f, 2.55f}, {-0.224f, 0.4f, 2.55f}, {0.0f, 0.4f, 2.55f},
    {-1.3f, 0.728f, 2.55f}, {-0.728f, 1.3f, 2.55f}, {0.0f, 1.3f, 2.55f},
    {-1.3f, 0.728f, 2.4f}, {-0.728f, 1.3f, 2.4f}, {0.0f, 1.3f, 2.4f},
    // 263
    {0.224f, 0.4f, 2.55f}, {0.4f, 0.224f, 2.55f},
    {0.728f, 1.3f, 2.55f}, {1.3f, 0.728f, 2.55f},
    {0.728f, 1.3f, 2.4f}, {1.3f, 0.728f, 2.4f},
    // 269: bottom
    {0.0f, 0.0f, 0.0f},
    {1.5f, 0.0f, 0.15f}, {1.5f, 0.84f, 0.15f}, {0.84f, 1.5f, 0.15f}, {0.0f, 1.5f, 0.15f},
    {1.5f, 0.0f, 0.075f}, {1.5f, 0.84f, 0.075f}, {0.84f, 1.5f, 0.075f}, {0.0f, 1.5f, 0.075f},
    {1.425f, 0.0f, 0.0f}, {1.425f, 0.798f, 0.0f}, {0.798f, 1.425f, 0.0f}, {0.0f, 1.425f, 0.0f},
    // 282
    {-0.84f, 1.5f, 0.15f}, {-1.5f, 0.84f, 0.15f}, {-1.5f, 0.0f, 0.15f},
    {-0.84f, 1.5f, 0.075f}, {-1.5f, 0.84f, 0.075f}, {-1.5f, 0.0f, 0.075f},
    {-0.798f, 1.425f, 0.0f}, {-1.425f, 0.798f, 0.0f}, {-1.425f, 0.0f, 0.0f},
    // 291
    {-1.5f, -0.84f, 0.15f}, {-0.84f, -1.5f, 0.15f}, {0.0f, -1.5f, 0.15f},
    {-1.5f, -0.84f, 0.075f}, {-0.84f, -1.5f, 0.075f}, {0.0f, -1.5f, 0.075f},
    {-1.425f, -0.798f, 0.0f}, {-0.798f, -1.425f, 0.0f}, {0.0f, -1.425f, 0.0f},
    // 300
    {0.84f, -1.5f, 0.15f}, {1.5f, -0.84f, 0.15f},
    {0.84f, -1.5f, 0.075f}, {1.5f, -0.84f, 0.075f},
    {0.798f, -1.425f, 0.0f}, {1.425f, -0.798f, 0.0f},
};

// Cubic Bernstein polynomials and their derivatives at x. At x = 0 and x = 1 the values are
// exactly 0 and 1, which makes points on a shared patch boundary bit-identical in both patches.
struct Bernstein {
    double b[4], db[4];
};

Bernstein bernstein(double x) {
    double y = 1.0 - x;
    Bernstein r;
    r.b[0] = y * y * y;
    r.b[1] = 3.0 * x * y * y;
    r.b[2] = 3.0 * x * x * y;
    r.b[3] = x * x * x;
    r.db[0] = -3.0 * y * y;
    r.db[1] = 3.0 * y * y - 6.0 * x * y;
    r.db[2] = 6.0 * x * y - 3.0 * x * x;
    r.db[3] = 3.0 * x * x;
    return r;
}

struct PatchPoint {
    Vec3d p, dp_ds, dp_dt;  // position and derivatives along rows (s) and columns (t)
};

// P(s, t) = sum_i sum_j B_i(s) B_j(t) C_ij: first along each row (t), then across rows (s).
PatchPoint eval_patch(const Vec3d cp[16], double s, double t) {
    Bernstein bs = bernstein(s), bt = bernstein(t);
    PatchPoint r;
    r.p = r.dp_ds = r.dp_dt = Vec3d(0.0);
    for (int i = 0; i < 4; ++i) {
        Vec3d row(0.0), row_dt(0.0);
        for (int j = 0; j < 4; ++j) {
            row += cp[4 * i + j] * bt.b[j];
            row_dt += cp[4 * i + j] * bt.db[j];
        }
        r.p += row * bs.b[i];
        r.dp_ds += row * bs.db[i];
        r.dp_dt += row_dt * bs.b[i];
    }
    return r;
}

// Outward unit normal at (s, t). Where the cross product of the derivatives vanishes (a pole,
// where a whole row of control points coincides) the normal is taken at a parameter nudged
// towards the middle of the patch, by growing steps until it is well defined.
Vec3d patch_normal(const Vec3d cp[16], double s, double t, double scale2) {
    const double kDegenerate = 1e-10 * scale2;
    const double nudges[] = {0.0, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1};
    for (double d : nudges) {
        double ss = s + (s < 0.5 ? d : -d), tt = t + (t < 0.5 ? d : -d);
        PatchPoint pp = eval_patch(cp, ss, tt);
        Vec3d n = cross(pp.dp_dt, pp.dp_ds);
        double len = length(n);
        if (len > kDegenerate) return n / len;
    }
    throw std::logic_error("make_teapot: no well-defined normal near a patch point");
}

}  // namespace

int64_t teapot_triangle_count(int n) {
    // With a single quad per patch, the four corners of each spout-tip patch are collinear.
    if (n == 1) return 52;
    return 64 * int64_t(n) * n - 8 * int64_t(n);
}

MeshData make_teapot(int subdivisions, bool y_up) {
    if (subdivisions < 1 || subdivisions > 1024)
        throw std::invalid_argument("make_teapot: subdivisions must be in [1, 1024], got " +
                                    std::to_string(subdivisions));
    const int n = subdivisions;
    const int64_t per_patch = int64_t(n + 1) * (n + 1);
    MeshData m;
    m.vertices.reserve(size_t(kNumPatches * per_patch * 3));
    m.normals.reserve(size_t(kNumPatches * per_patch * 3));
    m.uvs.reserve(size_t(kNumPatches * per_patch * 2));
    m.indices.reserve(size_t(teapot_triangle_count(n) * 3));

    // z up -> y up: (x, y, z) -> (x, z, -y), a rotation about x.
    auto orient = [&](const Vec3d& v) { return y_up ? Vec3f(float(v.x), float(v.z), float(-v.y)) : Vec3f(v); };

    for (int patch = 0; patch < kNumPatches; ++patch) {
        Vec3d cp[16];
        Vec3d lo(1e30), hi(-1e30);
        for (int k = 0; k < 16; ++k) {
            const float* q = kPoints[kPatches[patch][k]];
            cp[k] = Vec3d(q[0], q[1], q[2]);
            for (int c = 0; c < 3; ++c) {
                lo[c] = std::min(lo[c], cp[k][c]);
                hi[c] = std::max(hi[c], cp[k][c]);
            }
        }
        double scale2 = length_squared(hi - lo);

        const int32_t base = int32_t(m.num_vertices());
        for (int a = 0; a <= n; ++a) {
            double s = double(a) / n;
            for (int b = 0; b <= n; ++b) {
                double t = double(b) / n;
                Vec3f p = orient(eval_patch(cp, s, t).p);
                Vec3f nn = normalize(orient(patch_normal(cp, s, t, scale2)));
                m.vertices.insert(m.vertices.end(), {p.x, p.y, p.z});
                m.normals.insert(m.normals.end(), {nn.x, nn.y, nn.z});
                m.uvs.insert(m.uvs.end(), {float(t), float(s)});
            }
        }

        // Quad (a, b)-(a + 1, b + 1) as two triangles wound so that their face normal agrees with
        // cross(dP/dt, dP/ds): (00, 01, 11) and (00, 11, 10).
        auto vid = [&](int a, int b) { return base + int32_t(a * (n + 1) + b); };
        auto emit = [&](int32_t i0, int32_t i1, int32_t i2) {
            Vec3f v0 = Vec3f::load(&m.vertices[3 * size_t(i0)]), v1 = Vec3f::load(&m.vertices[3 * size_t(i1)]),
                  v2 = Vec3f::load(&m.vertices[3 * size_t(i2)]);
            // The same test as the scene's validation (double cross product of float edges),
            // with a relative threshold so that no sliver of rounding noise survives.
            Vec3d e1(v1 - v0), e2(v2 - v0);
            double area2 = length(cross(e1, e2));
            double edge2 = std::max(length_squared(e1), std::max(length_squared(e2), length_squared(Vec3d(v2 - v1))));
            if (!(area2 > 1e-10 * edge2)) return;
            m.indices.insert(m.indices.end(), {i0, i1, i2});
        };
        for (int a = 0; a < n; ++a)
            for (int b = 0; b < n; ++b) {
                emit(vid(a, b), vid(a, b + 1), vid(a + 1, b + 1));
                emit(vid(a, b), vid(a + 1, b + 1), vid(a + 1, b));
            }
    }
    return m;
}

}  // namespace edgepath
