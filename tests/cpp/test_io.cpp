// Tests for src/io: image round trips, reading conformance EXRs, OBJ loading.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <tuple>
#include <utility>

#include "io/image.h"
#include "io/obj.h"

namespace fs = std::filesystem;
using namespace edgepath;

namespace {

// A fresh directory per test, removed afterwards.
class IoTest : public ::testing::Test {
protected:
    void SetUp() override {
        std::string pattern = (fs::temp_directory_path() / "edgepath_io_XXXXXX").string();
        ASSERT_NE(mkdtemp(pattern.data()), nullptr);
        dir_ = pattern;
    }
    void TearDown() override {
        std::error_code ignored;
        fs::remove_all(dir_, ignored);
    }
    std::string path(const std::string& name) const { return (dir_ / name).string(); }
    void write_text(const std::string& name, const std::string& text) const {
        std::ofstream(dir_ / name) << text;
    }
    fs::path dir_;
};

// The conformance data set sits in the folder beside the repository; absent in some checkouts.
fs::path conformance_dir() {
    return fs::path(EDGEPATH_SOURCE_DIR).parent_path() / "shared" / "conformance" / "mitsuba3";
}

Image gradient_image(int height, int width, int channels) {
    Image image;
    image.height = height;
    image.width = width;
    image.channels = channels;
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x)
            for (int c = 0; c < channels; ++c)
                image.pixels.push_back((x + 2.f * y + 0.3f * c) / (width + 2.f * height));
    return image;
}

}  // namespace

TEST(Srgb, CurveRoundTripsAndHitsKnownValues) {
    EXPECT_FLOAT_EQ(srgb_to_linear(0.f), 0.f);
    EXPECT_NEAR(srgb_to_linear(1.f), 1.f, 1e-6f);
    EXPECT_NEAR(srgb_to_linear(0.5f), 0.21404f, 1e-5f);
    for (float x : {0.001f, 0.01f, 0.2f, 0.5f, 0.9f})
        EXPECT_NEAR(srgb_to_linear(linear_to_srgb(x)), x, 1e-6f);
}

TEST_F(IoTest, ExrRoundTripIsExact) {
    for (int channels : {1, 3, 4}) {
        Image image = gradient_image(5, 7, channels);
        image.pixels[3] = 12.5f;  // EXR keeps values above 1
        image.pixels[4] = -0.25f;
        const std::string file = path("image" + std::to_string(channels) + ".exr");
        write_image(file, image);
        const Image back = read_image(file);
        ASSERT_EQ(back.height, 5);
        ASSERT_EQ(back.width, 7);
        ASSERT_EQ(back.channels, channels);
        EXPECT_EQ(back.pixels, image.pixels);
    }
}

TEST_F(IoTest, PngRoundTripWithinQuantisation) {
    for (int channels : {1, 2, 3, 4}) {
        const Image image = gradient_image(4, 6, channels);
        const std::string file = path("image" + std::to_string(channels) + ".png");
        write_image(file, image);
        const Image back = read_image(file);
        ASSERT_EQ(back.height, 4);
        ASSERT_EQ(back.width, 6);
        ASSERT_EQ(back.channels, channels);
        for (size_t i = 0; i < image.pixels.size(); ++i) {
            // Half an 8-bit step times the largest slope of the sRGB decode (2.27, at 1).
            EXPECT_NEAR(back.pixels[i], image.pixels[i], 1.2f / 255.f) << "sample " << i;
        }
    }
}

TEST_F(IoTest, PngWriteClampsAndZeroesNan) {
    Image image;
    image.height = 1;
    image.width = 3;
    image.channels = 1;
    image.pixels = {-1.f, 7.f, std::nanf("")};
    write_image(path("clamp.png"), image);
    const Image back = read_image(path("clamp.png"));
    EXPECT_FLOAT_EQ(back.pixels[0], 0.f);
    EXPECT_NEAR(back.pixels[1], 1.f, 1e-6f);
    EXPECT_FLOAT_EQ(back.pixels[2], 0.f);
}

TEST_F(IoTest, ErrorsNameThePath) {
    const std::string missing = path("missing.exr");
    try {
        read_image(missing);
        FAIL() << "no exception";
    } catch (const IoError& e) {
        EXPECT_NE(std::string(e.what()).find(missing), std::string::npos) << e.what();
    }
    write_text("garbage.png", "not a png");
    EXPECT_THROW(read_image(path("garbage.png")), IoError);
    write_text("garbage.jpg", "not a jpeg");
    EXPECT_THROW(read_image(path("garbage.jpg")), IoError);
    write_text("garbage.exr", "not an exr");
    EXPECT_THROW(read_image(path("garbage.exr")), IoError);
    EXPECT_THROW(read_image(path("image.bmp")), std::invalid_argument);
    const Image image = gradient_image(2, 2, 3);
    EXPECT_THROW(write_image(path("image.jpg"), image), std::invalid_argument);
    EXPECT_THROW(write_image(path("image.exr"), image.pixels.data(), 2, 2, 5),
                 std::invalid_argument);
    EXPECT_THROW(write_image(path("no_such_dir/image.png"), image), IoError);
}

namespace {

// CRC-32 as PNG chunks carry it (ISO 3309), bit by bit.
uint32_t png_crc(const std::string& bytes) {
    uint32_t crc = 0xFFFFFFFFu;
    for (unsigned char byte : bytes) {
        crc ^= byte;
        for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
    }
    return crc ^ 0xFFFFFFFFu;
}

std::string big_endian(uint32_t v) {
    return {char(v >> 24), char(v >> 16), char(v >> 8), char(v)};
}

std::string read_bytes(const std::string& file) {
    std::ifstream in(file, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
}

}  // namespace

// A PNG whose header (with a valid CRC) declares a huge size is refused before its rows are
// allocated: beyond kMaxImagePixels, or more rows than its bytes can hold.
TEST_F(IoTest, PngDeclaringHugeSizesIsRefusedBeforeAllocating) {
    write_image(path("small.png"), gradient_image(4, 4, 3));
    const std::string png = read_bytes(path("small.png"));
    ASSERT_EQ(png.substr(12, 4), "IHDR");
    for (auto [width, height, words] : {std::tuple{60000u, 60000u, "at most"},
                                        std::tuple{16384u, 16384u, "bytes can hold"}}) {
        const std::string body = "IHDR" + big_endian(width) + big_endian(height) + png.substr(24, 5);
        const std::string patched = png.substr(0, 12) + body + big_endian(png_crc(body)) +
                                    png.substr(33);
        const std::string file = path("huge.png");
        std::ofstream(file, std::ios::binary) << patched;
        try {
            read_image(file);
            FAIL() << "no exception for " << width << "x" << height;
        } catch (const IoError& e) {
            const std::string message = e.what();
            EXPECT_NE(message.find(file + ": the file declares " + std::to_string(width) + "x" +
                                   std::to_string(height)), std::string::npos) << message;
            EXPECT_NE(message.find(words), std::string::npos) << message;
        }
    }
}

TEST_F(IoTest, ObjTextErrorsNameTheLine) {
    const std::string triangle = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
    const std::pair<std::string, int> cases[] = {
        {triangle + "f 1 2\n", 4},           {"v 0 0 0\nv 1 y 0\n", 2},
        {"v 0 0\n", 1},                      {triangle + "vn 0 0 1e40\n", 4},
        {triangle + "f 1 2 0x3\n", 4},       {triangle + "f 1 2 3\n" + std::string(1, '\0') + "\n", 5},
        {"# c\nv inf 0 0\n", 2},            {triangle + "f 1/1/1/1 2 3\n", 4},
    };
    for (const auto& [text, line] : cases) {
        const std::string file = path("bad.obj");
        std::ofstream(file, std::ios::binary) << text;
        try {
            load_obj(file);
            FAIL() << "no exception for " << text;
        } catch (const IoError& e) {
            EXPECT_EQ(std::string(e.what()).rfind(file + ":" + std::to_string(line) + ": ", 0), 0u)
                << e.what();
        }
    }
}

TEST(ConformanceImages, ReadsPizCompressedExr) {
    const fs::path refs = conformance_dir() / "refs";
    const fs::path museum = conformance_dir() / "textures" / "museum.exr";
    if (!fs::exists(museum)) GTEST_SKIP() << "conformance data not found at " << conformance_dir();
    const Image ref = read_image((refs / "test_diffuse_albedo_image_primal_ref.exr").string());
    EXPECT_GT(ref.height, 0);
    EXPECT_EQ(ref.height, ref.width);  // the references are square
    EXPECT_EQ(ref.channels, 3);
    float sum = 0.f;
    for (float v : ref.pixels) {
        ASSERT_TRUE(std::isfinite(v));
        sum += v;
    }
    EXPECT_GT(sum, 0.f);

    const Image env = read_image(museum.string());
    EXPECT_GT(env.height, 1);
    EXPECT_GT(env.width, 1);
    EXPECT_GE(env.channels, 3);
    for (float v : env.pixels) ASSERT_TRUE(std::isfinite(v));
}

TEST(ConformanceImages, ReadsJpegLinearised) {
    const fs::path jpg = conformance_dir() / "textures" / "gradient.jpg";
    if (!fs::exists(jpg)) GTEST_SKIP() << "conformance data not found at " << conformance_dir();
    const Image image = read_image(jpg.string());
    EXPECT_GT(image.height, 0);
    EXPECT_GT(image.width, 0);
    EXPECT_TRUE(image.channels == 1 || image.channels == 3);
    for (float v : image.pixels) {
        ASSERT_GE(v, 0.f);
        ASSERT_LE(v, 1.f);
    }
}

TEST_F(IoTest, ObjGroupsByMaterialAndFlipsV) {
    write_text("scene.mtl",
               "newmtl red\nKd 0.8 0.1 0.1\nKs 0.04 0.04 0.04\nNs 98\nmap_Kd tex/red.png\n"
               "newmtl lamp\nKd 0 0 0\nKe 5 4 3\n");
    write_text("scene.obj",
               "mtllib scene.mtl\n"
               "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 5 5 5\n"
               "vt 0 0\nvt 1 0\nvt 1 0.25\nvt 0 1\n"
               "vn 0 0 1\n"
               "usemtl red\n"
               "f 1/1/1 2/2/1 3/3/1 4/4/1\n"  // a quad: two triangles
               "usemtl lamp\n"
               "f 5 2 3\n");
    const std::vector<ObjMesh> meshes = load_obj(path("scene.obj"));
    ASSERT_EQ(meshes.size(), 2u);

    const ObjMesh& red = meshes[0];
    EXPECT_EQ(red.material.name, "red");
    EXPECT_TRUE(red.material.defined);
    EXPECT_EQ(red.num_triangles(), 2);
    EXPECT_EQ(red.positions.size(), 4u * 3);
    EXPECT_EQ(red.uvs.size(), 4u * 2);
    EXPECT_EQ(red.normals.size(), 1u * 3);
    EXPECT_EQ(red.uv_indices.size(), red.indices.size());
    EXPECT_EQ(red.normal_indices.size(), red.indices.size());
    EXPECT_FLOAT_EQ(red.material.diffuse[0], 0.8f);
    EXPECT_FLOAT_EQ(red.material.specular[1], 0.04f);
    EXPECT_FLOAT_EQ(red.material.roughness, std::sqrt(2.f / 100.f));
    EXPECT_EQ(red.material.diffuse_texture, path("tex/red.png"));
    // The corner at position (1, 1, 0) has vt 1 0.25: v flipped to 0.75.
    int corners_found = 0;
    for (size_t k = 0; k < red.indices.size(); ++k) {
        const float* p = &red.positions[3 * red.indices[k]];
        if (p[0] == 1.f && p[1] == 1.f) {
            EXPECT_FLOAT_EQ(red.uvs[2 * red.uv_indices[k]], 1.f);
            EXPECT_FLOAT_EQ(red.uvs[2 * red.uv_indices[k] + 1], 0.75f);
            ++corners_found;
        }
    }
    EXPECT_GE(corners_found, 1);
    for (int32_t i : red.indices) EXPECT_LT(i, 4);

    const ObjMesh& lamp = meshes[1];
    EXPECT_EQ(lamp.material.name, "lamp");
    EXPECT_EQ(lamp.num_triangles(), 1);
    EXPECT_EQ(lamp.positions.size(), 3u * 3);  // only the vertices it uses
    EXPECT_TRUE(lamp.uvs.empty());
    EXPECT_TRUE(lamp.uv_indices.empty());
    EXPECT_TRUE(lamp.normals.empty());
    EXPECT_FLOAT_EQ(lamp.material.emission[0], 5.f);
    EXPECT_FLOAT_EQ(lamp.positions[3 * lamp.indices[0]], 5.f);
}

TEST_F(IoTest, ObjWithoutMaterialsAndBadFiles) {
    write_text("plain.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    const std::vector<ObjMesh> meshes = load_obj(path("plain.obj"));
    ASSERT_EQ(meshes.size(), 1u);
    EXPECT_FALSE(meshes[0].material.defined);
    EXPECT_EQ(meshes[0].num_triangles(), 1);
    EXPECT_EQ(meshes[0].indices, (std::vector<int32_t>{0, 1, 2}));

    EXPECT_THROW(load_obj(path("missing.obj")), IoError);
    write_text("mixed.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 3/1\nf 1 2 3\n");
    EXPECT_THROW(load_obj(path("mixed.obj")), IoError);
}

TEST(ConformanceMeshes, RectangleObj) {
    const fs::path obj = conformance_dir() / "meshes" / "rectangle.obj";
    if (!fs::exists(obj)) GTEST_SKIP() << "conformance data not found at " << conformance_dir();
    const std::vector<ObjMesh> meshes = load_obj(obj.string());
    ASSERT_EQ(meshes.size(), 1u);
    const ObjMesh& mesh = meshes[0];
    EXPECT_EQ(mesh.num_triangles(), 2);
    ASSERT_EQ(mesh.uv_indices.size(), 6u);
    // After the v flip, uv = ((x + 1) / 2, (y + 1) / 2) at every corner (see the data's README).
    for (size_t k = 0; k < 6; ++k) {
        const float* p = &mesh.positions[3 * mesh.indices[k]];
        const float* t = &mesh.uvs[2 * mesh.uv_indices[k]];
        EXPECT_FLOAT_EQ(t[0], (p[0] + 1.f) / 2.f);
        EXPECT_FLOAT_EQ(t[1], (p[1] + 1.f) / 2.f);
    }
}
