// Image files through libpng, libjpeg(-turbo) and OpenEXR 3.
//
// libpng and libjpeg report errors by longjmp. Each reader/writer below declares every object
// with a destructor before its setjmp call, so a longjmp back into the function skips no
// destructor; the error branch then cleans up the library state and throws IoError.
#include "io/image.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <memory>

#include <png.h>
// jpeglib.h needs FILE and size_t declared first.
#include <jpeglib.h>
#include <jerror.h>  // the message codes

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfOutputFile.h>

namespace edgepath {

float srgb_to_linear(float c) {
    if (c <= 0.04045f) return c / 12.92f;
    return std::pow((c + 0.055f) / 1.055f, 2.4f);
}

float linear_to_srgb(float x) {
    if (x <= 0.0031308f) return 12.92f * x;
    return 1.055f * std::pow(x, 1.f / 2.4f) - 0.055f;
}

namespace {

struct FileCloser {
    void operator()(std::FILE* f) const {
        if (f) std::fclose(f);
    }
};
using FilePtr = std::unique_ptr<std::FILE, FileCloser>;

FilePtr open_file(const std::string& path, const char* mode) {
    std::FILE* f = std::fopen(path.c_str(), mode);
    if (!f) throw IoError(path + ": cannot open (" + std::strerror(errno) + ")");
    return FilePtr(f);
}

void close_written_file(FilePtr& file, const std::string& path) {
    std::FILE* f = file.release();
    if (std::fclose(f) != 0) throw IoError(path + ": write failed (" + std::strerror(errno) + ")");
}

std::string lowercase_extension(const std::string& path) {
    const size_t slash = path.find_last_of("/\\");
    const size_t dot = path.find_last_of('.');
    if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
    std::string ext = path.substr(dot + 1);
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char ch) { return static_cast<char>(std::tolower(ch)); });
    return ext;
}

// Refuses sizes that are empty or larger than kMaxImagePixels, before anything is allocated.
void check_image_size(const std::string& path, long long width, long long height) {
    if (width <= 0 || height <= 0 || width > kMaxImagePixels || height > kMaxImagePixels ||
        width * height > kMaxImagePixels)
        throw IoError(path + ": the file declares " + std::to_string(width) + "x" +
                      std::to_string(height) + " pixels (at most " +
                      std::to_string(kMaxImagePixels) + " pixels are read)");
}

long long file_size(std::FILE* file) {
    const long position = std::ftell(file);
    std::fseek(file, 0, SEEK_END);
    const long size = std::ftell(file);
    std::fseek(file, position, SEEK_SET);
    return size;
}

// True for the channels of a `channels`-channel image that hold colour (not alpha).
bool is_colour_channel(int channel, int channels) {
    return !((channels == 2 && channel == 1) || (channels == 4 && channel == 3));
}

// Decodes 8- or 16-bit integer samples to float, sRGB-decoding the colour channels.
template <typename Sample>
void decode_samples(const Sample* samples, int channels, size_t count, float* out) {
    constexpr float max_value = static_cast<float>((1u << (8 * sizeof(Sample))) - 1u);
    // A table for 8-bit data; 16-bit data is rare enough to convert directly.
    static const std::vector<float> srgb8 = [] {
        std::vector<float> table(256);
        for (int i = 0; i < 256; ++i) table[i] = srgb_to_linear(i / 255.f);
        return table;
    }();
    for (size_t i = 0; i < count; ++i) {
        const int channel = static_cast<int>(i % channels);
        const Sample s = samples[i];
        if (!is_colour_channel(channel, channels))
            out[i] = s / max_value;
        else if constexpr (sizeof(Sample) == 1)
            out[i] = srgb8[s];
        else
            out[i] = srgb_to_linear(s / max_value);
    }
}

// ---- PNG ----------------------------------------------------------------------------------

struct PngState {
    png_structp png = nullptr;
    png_infop info = nullptr;
    bool writing = false;
    std::string message;
    ~PngState() {
        if (writing)
            png_destroy_write_struct(&png, info ? &info : nullptr);
        else
            png_destroy_read_struct(&png, info ? &info : nullptr, nullptr);
    }
};

void png_error_handler(png_structp png, png_const_charp message) {
    static_cast<PngState*>(png_get_error_ptr(png))->message = message ? message : "libpng error";
    png_longjmp(png, 1);
}

void png_warning_handler(png_structp, png_const_charp) {}  // e.g. "known incorrect sRGB profile"

Image read_png(const std::string& path) {
    FilePtr file = open_file(path, "rb");
    png_byte signature[8];
    if (std::fread(signature, 1, 8, file.get()) != 8 || png_sig_cmp(signature, 0, 8) != 0)
        throw IoError(path + ": not a PNG file");

    PngState state;
    Image image;
    std::vector<png_byte> buffer;
    std::vector<png_bytep> rows;
    state.png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &state, png_error_handler,
                                       png_warning_handler);
    if (!state.png) throw IoError(path + ": cannot create a PNG reader");
    state.info = png_create_info_struct(state.png);
    if (!state.info) throw IoError(path + ": cannot create a PNG reader");
    if (setjmp(png_jmpbuf(state.png))) throw IoError(path + ": " + state.message);

    png_init_io(state.png, file.get());
    png_set_sig_bytes(state.png, 8);
    png_read_info(state.png, state.info);
    const png_byte color_type = png_get_color_type(state.png, state.info);
    const png_byte depth = png_get_bit_depth(state.png, state.info);
    {
        const long long width = png_get_image_width(state.png, state.info);
        const long long height = png_get_image_height(state.png, state.info);
        check_image_size(path, width, height);
        // Deflate packs at most 1032 bytes into one: a file too small for the rows it declares
        // is truncated or lying, and is refused before the rows are allocated.
        const long long raw = (width * png_get_channels(state.png, state.info) * depth + 7) / 8 *
                              height + height;
        if (raw / 1032 > file_size(file.get()))
            throw IoError(path + ": the file declares " + std::to_string(width) + "x" +
                          std::to_string(height) + " pixels, more than its " +
                          std::to_string(file_size(file.get())) + " bytes can hold");
    }
    if (color_type == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(state.png);
    if (color_type == PNG_COLOR_TYPE_GRAY && depth < 8) png_set_expand_gray_1_2_4_to_8(state.png);
    if (png_get_valid(state.png, state.info, PNG_INFO_tRNS)) png_set_tRNS_to_alpha(state.png);
    if (depth == 16) png_set_swap(state.png);  // native (little-endian) 16-bit samples
    png_set_interlace_handling(state.png);
    png_read_update_info(state.png, state.info);

    image.width = static_cast<int>(png_get_image_width(state.png, state.info));
    image.height = static_cast<int>(png_get_image_height(state.png, state.info));
    image.channels = png_get_channels(state.png, state.info);
    const size_t row_bytes = png_get_rowbytes(state.png, state.info);
    buffer.resize(row_bytes * image.height);
    rows.resize(image.height);
    for (int y = 0; y < image.height; ++y) rows[y] = buffer.data() + row_bytes * y;
    png_read_image(state.png, rows.data());
    png_read_end(state.png, nullptr);

    const size_t count = static_cast<size_t>(image.width) * image.height * image.channels;
    image.pixels.resize(count);
    if (png_get_bit_depth(state.png, state.info) == 16) {
        std::vector<uint16_t> samples(count);
        std::memcpy(samples.data(), buffer.data(), count * sizeof(uint16_t));
        decode_samples(samples.data(), image.channels, count, image.pixels.data());
    } else {
        decode_samples(buffer.data(), image.channels, count, image.pixels.data());
    }
    return image;
}

void write_png(const std::string& path, const float* pixels, int height, int width,
               int channels) {
    const size_t count = static_cast<size_t>(width) * height * channels;
    std::vector<png_byte> buffer(count);
    for (size_t i = 0; i < count; ++i) {
        float v = pixels[i];
        v = std::isnan(v) ? 0.f : std::min(std::max(v, 0.f), 1.f);
        if (is_colour_channel(static_cast<int>(i % channels), channels)) v = linear_to_srgb(v);
        buffer[i] = static_cast<png_byte>(std::lround(v * 255.f));
    }
    std::vector<png_bytep> rows(height);
    for (int y = 0; y < height; ++y)
        rows[y] = buffer.data() + static_cast<size_t>(y) * width * channels;

    FilePtr file = open_file(path, "wb");
    PngState state;
    state.writing = true;
    state.png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &state, png_error_handler,
                                        png_warning_handler);
    if (!state.png) throw IoError(path + ": cannot create a PNG writer");
    state.info = png_create_info_struct(state.png);
    if (!state.info) throw IoError(path + ": cannot create a PNG writer");
    if (setjmp(png_jmpbuf(state.png))) throw IoError(path + ": " + state.message);

    static const int color_types[] = {PNG_COLOR_TYPE_GRAY, PNG_COLOR_TYPE_GRAY_ALPHA,
                                      PNG_COLOR_TYPE_RGB, PNG_COLOR_TYPE_RGB_ALPHA};
    png_init_io(state.png, file.get());
    png_set_IHDR(state.png, state.info, width, height, 8, color_types[channels - 1],
                 PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    png_set_sRGB_gAMA_and_cHRM(state.png, state.info, PNG_sRGB_INTENT_PERCEPTUAL);
    png_write_info(state.png, state.info);
    png_write_image(state.png, rows.data());
    png_write_end(state.png, nullptr);
    close_written_file(file, path);
}

// ---- JPEG ---------------------------------------------------------------------------------

struct JpegErrorManager {
    jpeg_error_mgr base;  // first member: libjpeg hands us a pointer to it
    std::jmp_buf jump;
    char message[JMSG_LENGTH_MAX];
};

void jpeg_error_handler(j_common_ptr info) {
    auto* errors = reinterpret_cast<JpegErrorManager*>(info->err);
    (*info->err->format_message)(info, errors->message);
    std::longjmp(errors->jump, 1);
}

void jpeg_message_handler(j_common_ptr) {}  // warnings are not fatal; stay quiet

// Warnings of lost data (the file ends early, a marker where data should be) are errors:
// libjpeg would fill the missing rows with grey.
void jpeg_emit_handler(j_common_ptr info, int level) {
    const int code = info->err->msg_code;
    if (level < 0 && (code == JWRN_JPEG_EOF || code == JWRN_HIT_MARKER || code == JWRN_MUST_RESYNC))
        jpeg_error_handler(info);
}

Image read_jpeg(const std::string& path) {
    FilePtr file = open_file(path, "rb");
    Image image;
    std::vector<JSAMPLE> row;
    jpeg_decompress_struct info;
    std::memset(&info, 0, sizeof(info));
    JpegErrorManager errors;
    info.err = jpeg_std_error(&errors.base);
    errors.base.error_exit = jpeg_error_handler;
    errors.base.output_message = jpeg_message_handler;
    errors.base.emit_message = jpeg_emit_handler;
    if (setjmp(errors.jump)) {
        jpeg_destroy_decompress(&info);
        throw IoError(path + ": " + errors.message);
    }
    jpeg_create_decompress(&info);
    jpeg_stdio_src(&info, file.get());
    jpeg_read_header(&info, TRUE);
    check_image_size(path, info.image_width, info.image_height);
    // Progressive files keep all coefficients in memory: bound it (beyond, libjpeg errors).
    info.mem->max_memory_to_use = 8 * kMaxImagePixels;
    info.out_color_space = info.num_components == 1 ? JCS_GRAYSCALE : JCS_RGB;
    jpeg_start_decompress(&info);

    image.width = static_cast<int>(info.output_width);
    image.height = static_cast<int>(info.output_height);
    image.channels = info.output_components;
    const size_t row_size = static_cast<size_t>(image.width) * image.channels;
    row.resize(row_size);
    while (info.output_scanline < info.output_height) {
        const size_t y = info.output_scanline;
        JSAMPROW rows[1] = {row.data()};
        jpeg_read_scanlines(&info, rows, 1);
        // Grown row by row: a file that declares more rows than it holds fails before
        // its declared size is allocated.
        image.pixels.resize((y + 1) * row_size);
        decode_samples(row.data(), image.channels, row_size, image.pixels.data() + y * row_size);
    }
    jpeg_finish_decompress(&info);
    jpeg_destroy_decompress(&info);
    return image;
}

// ---- OpenEXR ------------------------------------------------------------------------------

// A name from a file, with bytes outside printable ASCII written as \xNN (messages are UTF-8).
std::string printable(const char* name) {
    static const char digits[] = "0123456789abcdef";
    std::string out;
    for (const char* p = name; *p; ++p) {
        const unsigned char c = static_cast<unsigned char>(*p);
        if (c >= 0x20 && c < 0x7f) {
            out += static_cast<char>(c);
        } else {
            out += "\\x";
            out += digits[c >> 4];
            out += digits[c & 15];
        }
    }
    return out;
}

Image read_exr(const std::string& path) {
    try {
        Imf::InputFile file(path.c_str());
        const Imf::Header& header = file.header();
        const Imath::Box2i window = header.dataWindow();
        const Imf::ChannelList& available = header.channels();
        std::vector<const char*> names;
        if (available.findChannel("R") && available.findChannel("G") && available.findChannel("B"))
            names = {"R", "G", "B"};
        else if (available.findChannel("Y"))
            names = {"Y"};
        if (names.empty()) {
            std::string found;
            for (auto it = available.begin(); it != available.end(); ++it)
                found += std::string(found.empty() ? "" : ",") + printable(it.name());
            throw IoError(path + ": no R,G,B or Y channels (found: " + found + ")");
        }
        if (available.findChannel("A")) names.push_back("A");

        Image image;
        check_image_size(path, static_cast<long long>(window.max.x) - window.min.x + 1,
                         static_cast<long long>(window.max.y) - window.min.y + 1);
        image.width = window.max.x - window.min.x + 1;
        image.height = window.max.y - window.min.y + 1;
        image.channels = static_cast<int>(names.size());
        image.pixels.assign(static_cast<size_t>(image.width) * image.height * image.channels, 0.f);
        const size_t x_stride = sizeof(float) * image.channels;
        const size_t y_stride = x_stride * image.width;
        Imf::FrameBuffer frame;
        for (int c = 0; c < image.channels; ++c)
            frame.insert(names[c], Imf::Slice::Make(Imf::FLOAT, image.pixels.data() + c, window,
                                                    x_stride, y_stride));
        file.setFrameBuffer(frame);
        file.readPixels(window.min.y, window.max.y);
        return image;
    } catch (const IoError&) {
        throw;
    } catch (const std::exception& e) {
        throw IoError(path + ": " + e.what());
    }
}

void write_exr(const std::string& path, const float* pixels, int height, int width,
               int channels) {
    static const std::vector<std::vector<const char*>> names_by_count = {
        {"Y"}, {"Y", "A"}, {"R", "G", "B"}, {"R", "G", "B", "A"}};
    const std::vector<const char*>& names = names_by_count[channels - 1];
    try {
        Imf::Header header(width, height);
        header.compression() = Imf::ZIP_COMPRESSION;
        for (const char* name : names) header.channels().insert(name, Imf::Channel(Imf::FLOAT));
        const size_t x_stride = sizeof(float) * channels;
        const size_t y_stride = x_stride * width;
        Imf::FrameBuffer frame;
        for (int c = 0; c < channels; ++c) {
            // OpenEXR's Slice takes a mutable pointer but only reads from it when writing.
            char* base = reinterpret_cast<char*>(const_cast<float*>(pixels + c));
            frame.insert(names[c], Imf::Slice(Imf::FLOAT, base, x_stride, y_stride));
        }
        Imf::OutputFile file(path.c_str(), header);
        file.setFrameBuffer(frame);
        file.writePixels(height);
    } catch (const std::exception& e) {
        throw IoError(path + ": " + e.what());
    }
}

}  // namespace

Image read_image(const std::string& path) {
    const std::string ext = lowercase_extension(path);
    if (ext == "png") return read_png(path);
    if (ext == "jpg" || ext == "jpeg") return read_jpeg(path);
    if (ext == "exr") return read_exr(path);
    throw std::invalid_argument(path + ": unsupported image format '." + ext +
                                "' (expected .png, .jpg, .jpeg or .exr)");
}

void write_image(const std::string& path, const float* pixels, int height, int width,
                 int channels) {
    if (height <= 0 || width <= 0)
        throw std::invalid_argument(path + ": image size " + std::to_string(height) + "x" +
                                    std::to_string(width) + " is empty");
    if (channels < 1 || channels > 4)
        throw std::invalid_argument(path + ": " + std::to_string(channels) +
                                    " channels (expected 1 to 4)");
    if (!pixels) throw std::invalid_argument(path + ": no pixel data");
    const std::string ext = lowercase_extension(path);
    if (ext == "png") return write_png(path, pixels, height, width, channels);
    if (ext == "exr") return write_exr(path, pixels, height, width, channels);
    throw std::invalid_argument(path + ": unsupported image format '." + ext +
                                "' for writing (expected .png or .exr)");
}

}  // namespace edgepath
