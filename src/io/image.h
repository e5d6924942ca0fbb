// Image files: PNG and JPEG (8/16-bit sRGB, linearised on read) and OpenEXR (linear float).
// Images are (height, width, channels) float32, row 0 at the top, linear radiance/reflectance.
// Errors (missing file, corrupt data, unsupported layout) throw IoError naming the path.
#pragma once
#include <stdexcept>
#include <string>
#include <vector>

namespace edgepath {

// A file could not be read or written. The message starts with the path.
class IoError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

struct Image {
    int height = 0, width = 0, channels = 0;  // channels: 1 (Y), 2 (YA), 3 (RGB) or 4 (RGBA)
    std::vector<float> pixels;                // height * width * channels, row-major
    float at(int row, int col, int channel) const {
        return pixels[(static_cast<size_t>(row) * width + col) * channels + channel];
    }
};

// The most pixels an image file may declare (16384 x 16384): larger sizes are refused, before
// any pixel memory is allocated, with an IoError naming the file and the size.
constexpr long long kMaxImagePixels = 1ll << 28;

// The sRGB transfer curve (IEC 61966-2-1) and its inverse, on [0, 1].
float srgb_to_linear(float encoded);
float linear_to_srgb(float linear);

// Reads .png, .jpg/.jpeg or .exr (by extension, case-insensitive). PNG/JPEG colour channels are
// decoded from sRGB to linear; alpha stays as stored. EXR: channels R,G,B[,A] or Y[,A], any
// compression, scanline or tiled; returned as float32 unchanged.
Image read_image(const std::string& path);

// Writes .png (8-bit: colour channels clamped to [0, 1] and sRGB-encoded, NaN written as 0)
// or .exr (float32, ZIP compressed, linear). `pixels` is (height, width, channels) with 1 to 4
// channels. Unknown extensions and bad sizes throw std::invalid_argument.
void write_image(const std::string& path, const float* pixels, int height, int width,
                 int channels);
inline void write_image(const std::string& path, const Image& image) {
    write_image(path, image.pixels.data(), image.height, image.width, image.channels);
}

}  // namespace edgepath
