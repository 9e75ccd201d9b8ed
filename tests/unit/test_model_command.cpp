// Tests of the flash partition in a file and of `edgetrack model list|show|export|import`.
#include <sstream>

#include <gtest/gtest.h>

#include "core/marker_set.hpp"
#include "firmware_app/firmware/firmware_config.hpp"
#include "firmware_app/firmware/model_store.hpp"
#include "firmware_app/formats/model_file.hpp"
#include "firmware_app/tools/model_command.hpp"
#include "hal/linux/file_flash.hpp"
#include "hal/sim/scene.hpp"
#include "tests/support/layouts.hpp"
#include "tests/support/temp_dir.hpp"

namespace edgetrack::app {
namespace {

namespace fs = std::filesystem;

std::vector<Vec3> layoutOf(const sim::MarkerObject& object) {
    std::vector<Vec3> layout;
    for (const sim::SimMarker& m : object.markers)
        layout.push_back(m.position_object_mm);
    return layout;
}

TEST(FileFlash, ANewPartitionIsErasedAndWritesClearBitsOnly) {
    test::TempDir dir;
    linux_hal::FileFlash flash(dir.path() / "p.img", 8192, 4096);
    ASSERT_TRUE(flash.isValid()) << flash.error();
    EXPECT_EQ(fs::file_size(dir.path() / "p.img"), 8192u);
    std::array<std::uint8_t, 4> bytes{};
    ASSERT_TRUE(flash.read(4094, bytes));
    EXPECT_EQ(bytes, (std::array<std::uint8_t, 4>{0xFF, 0xFF, 0xFF, 0xFF}));
    const std::array<std::uint8_t, 2> first{0xF0, 0x0F};
    const std::array<std::uint8_t, 2> second{0x3C, 0xFF};
    ASSERT_TRUE(flash.write(100, first));
    ASSERT_TRUE(flash.write(100, second));
    std::array<std::uint8_t, 2> landed{};
    ASSERT_TRUE(flash.read(100, landed));
    EXPECT_EQ(landed, (std::array<std::uint8_t, 2>{0x30, 0x0F})) << "NOR: old & new";
    ASSERT_TRUE(flash.erase(0, 4096));
    ASSERT_TRUE(flash.read(100, landed));
    EXPECT_EQ(landed, (std::array<std::uint8_t, 2>{0xFF, 0xFF}));
    EXPECT_FALSE(flash.erase(100, 4096)) << "erase covers whole blocks";
    EXPECT_FALSE(flash.write(8191, first)) << "past the end";
}

TEST(FileFlash, ContentsSurviveAReopenAndAWrongSizeIsReadButNeverWritten) {
    test::TempDir dir;
    const std::array<std::uint8_t, 3> data{1, 2, 3};
    {
        linux_hal::FileFlash flash(dir.path() / "p.img", 8192, 4096);
        ASSERT_TRUE(flash.write(5000, data));
    }
    linux_hal::FileFlash again(dir.path() / "p.img", 8192, 4096);
    ASSERT_TRUE(again.isValid()) << again.error();
    std::array<std::uint8_t, 3> read{};
    ASSERT_TRUE(again.read(5000, read));
    EXPECT_EQ(read, (std::array<std::uint8_t, 3>{1, 2, 3}));
    // A file of another size stopped the board, which under Restart=on-failure restarted in a
    // loop and never tracked although the slots were intact: it is now read as far as it goes
    // (past its end as erased) and never written.
    linux_hal::FileFlash wrong(dir.path() / "p.img", 16384, 4096);
    ASSERT_TRUE(wrong.isValid()) << wrong.error();
    EXPECT_NE(wrong.warning().find("holds 8192 bytes, the partition is 16384"), std::string::npos)
        << wrong.warning();
    ASSERT_TRUE(wrong.read(5000, read));
    EXPECT_EQ(read, (std::array<std::uint8_t, 3>{1, 2, 3}));
    std::array<std::uint8_t, 4> beyond{};
    ASSERT_TRUE(wrong.read(8190, beyond));
    EXPECT_EQ(beyond, (std::array<std::uint8_t, 4>{0xFF, 0xFF, 0xFF, 0xFF}));
    EXPECT_FALSE(wrong.write(0, data));
    EXPECT_FALSE(wrong.erase(0, 4096));
    EXPECT_EQ(std::filesystem::file_size(dir.path() / "p.img"), 8192u) << "left as it was";
    linux_hal::FileFlash missing(dir.path() / "no" / "such" / "p.img", 8192, 4096);
    EXPECT_FALSE(missing.isValid());
}

TEST(ModelCommand, ImportListShowExportRoundTrip) {
    test::TempDir dir;
    const fs::path models = dir.path() / "models";
    fs::create_directories(models);
    MarkerModel cube = test::fullyConnectedModel(layoutOf(sim::makeCube70()), 0);
    MarkerModel small = test::fullyConnectedModel(layoutOf(sim::makeCube50()), 3);
    ASSERT_TRUE(writeModelJson(modelPath(models, 0), cube, "big cube"));
    ASSERT_TRUE(writeModelJson(modelPath(models, 3), small, "small cube"));
    const fs::path image = dir.path() / "models.flash";

    std::ostringstream out;
    ModelCommandOptions import;
    import.action = "import";
    import.models = models;
    import.flash = image;
    const Status imported = runModelCommand(import, out);
    ASSERT_TRUE(imported) << imported.error().message;
    EXPECT_NE(out.str().find("2 models saved to"), std::string::npos) << out.str();

    // The board's firmware reads the same partition through the model store.
    linux_hal::FileFlash flash(image, 1u << 20, 4096);
    ModelStore store(flash, MarkerSet::kCapacity);
    Result<StoredModels> stored = store.load();
    ASSERT_TRUE(stored) << stored.error().message;
    EXPECT_EQ(stored->models.size(), 2u);

    ModelCommandOptions list;
    list.action = "list";
    list.flash = image;
    out.str("");
    ASSERT_TRUE(runModelCommand(list, out));
    EXPECT_NE(out.str().find("body 0  30 markers"), std::string::npos) << out.str();
    EXPECT_NE(out.str().find("body 3  24 markers"), std::string::npos) << out.str();
    EXPECT_NE(out.str().find("small cube"), std::string::npos) << out.str();

    ModelCommandOptions show = list;
    show.action = "show";
    show.id = 3;
    out.str("");
    ASSERT_TRUE(runModelCommand(show, out));
    EXPECT_NE(out.str().find("body 3 (small cube): 24 markers"), std::string::npos) << out.str();
    show.id = 7;
    const Status none = runModelCommand(show, out);
    ASSERT_FALSE(none);
    EXPECT_EQ(none.error().message, "no model with id 7");

    ModelCommandOptions exported = list;
    exported.action = "export";
    exported.out = dir.path() / "exported";
    ASSERT_TRUE(runModelCommand(exported, out));
    Result<std::vector<NamedModel>> back = readModelDirectory(exported.out, MarkerSet::kCapacity);
    ASSERT_TRUE(back) << back.error().message;
    ASSERT_EQ(back->size(), 2u);
    EXPECT_EQ((*back)[1].model.id, 3u);
    EXPECT_EQ((*back)[1].name, "small cube");
    ASSERT_EQ((*back)[0].model.markers_model_mm.size(), 30u);
    for (std::size_t i = 0; i < 30; ++i)
        EXPECT_LT(((*back)[0].model.markers_model_mm[i] - cube.markers_model_mm[i]).norm(), 1e-3);
    EXPECT_FALSE(runModelCommand(exported, out)) << "refuses to write into a used directory";
}

TEST(ModelCommand, AMissingOrCorruptPartitionIsReported) {
    test::TempDir dir;
    std::ostringstream out;
    ModelCommandOptions list;
    list.action = "list";
    list.flash = dir.path() / "none.flash";
    Status s = runModelCommand(list, out);
    ASSERT_FALSE(s);
    EXPECT_NE(s.error().message.find("none.flash: no such flash partition"), std::string::npos)
        << s.error().message;
    { linux_hal::FileFlash erased(dir.path() / "empty.flash", 1u << 20, 4096); }
    list.flash = dir.path() / "empty.flash";
    s = runModelCommand(list, out);
    ASSERT_FALSE(s);
    EXPECT_NE(s.error().message.find("no models on flash: slot A empty, slot B empty"),
              std::string::npos)
        << s.error().message;
}

TEST(ModelCommand, ImportRefusesMoreModelsThanTheBoardKeeps) {
    // 100 models were saved while the board keeps 16: 84 showed only as a counter.
    test::TempDir dir;
    const fs::path models = dir.path() / "models";
    fs::create_directories(models);
    const std::vector<Vec3> layout = layoutOf(sim::makeCube50());
    const std::size_t keeps = FirmwareConfig{}.maxModels;
    for (std::uint32_t id = 0; id <= keeps; ++id)
        ASSERT_TRUE(writeModelJson(modelPath(models, id), test::fullyConnectedModel(layout, id),
                                   "cube " + std::to_string(id)));
    ModelCommandOptions import;
    import.action = "import";
    import.models = models;
    import.flash = dir.path() / "models.flash";
    std::ostringstream out;
    const Status s = runModelCommand(import, out);
    ASSERT_FALSE(s);
    EXPECT_NE(s.error().message.find(std::to_string(keeps + 1) +
                                     " models; the board keeps at most " + std::to_string(keeps)),
              std::string::npos)
        << s.error().message;
    EXPECT_FALSE(fs::exists(dir.path() / "models.flash")) << "nothing written";
}

} // namespace
} // namespace edgetrack::app
