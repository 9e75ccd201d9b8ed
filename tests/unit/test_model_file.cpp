// Tests of the model files of INTERFACES §4: round trip, and a clear error for each defect.
#include <fstream>
#include <string>

#include <gtest/gtest.h>

#include "firmware_app/formats/model_file.hpp"
#include "tests/support/temp_dir.hpp"

namespace edgetrack::app {
namespace {

MarkerModel sampleModel() {
    MarkerModel model(8);
    model.id = 3;
    model.sMin = 4;
    for (const Vec3& p : {Vec3(10.5, -3.25, 0.125), Vec3(-20.0, 4.0, 7.0), Vec3(0.0, 30.0, -5.5),
                          Vec3(12.0, 12.0, 12.0), Vec3(-8.0, -16.0, 3.0)})
        model.markers_model_mm.push_back(p);
    for (std::uint16_t i = 0; i < 5; ++i)
        for (std::uint16_t j = static_cast<std::uint16_t>(i + 1); j < 5; ++j)
            if (!(i == 0 && j == 4))
                model.edges.push_back(
                    {i, j, (model.markers_model_mm[i] - model.markers_model_mm[j]).norm()});
    return model;
}

std::string errorOf(const std::string& text, std::size_t maxMarkers = 64) {
    const Result<NamedModel> m = parseModelJson(text, "body_9.json", maxMarkers);
    return m ? std::string("no error") : m.error().message;
}

TEST(ModelFile, RoundTripKeepsEveryField) {
    test::TempDir dir;
    const MarkerModel model = sampleModel();
    ASSERT_TRUE(writeModelJson(modelPath(dir.path(), model.id), model, "the \"red\" cube"));
    const Result<NamedModel> read = readModelJson(dir.path() / "body_3.json", 64);
    ASSERT_TRUE(read) << read.error().message;
    EXPECT_EQ(read->name, "the \"red\" cube");
    EXPECT_EQ(read->model.id, 3u);
    EXPECT_EQ(read->model.sMin, 4u);
    ASSERT_EQ(read->model.markers_model_mm.size(), 5u);
    for (std::size_t i = 0; i < 5; ++i)
        EXPECT_LT((read->model.markers_model_mm[i] - model.markers_model_mm[i]).norm(), 1e-4);
    ASSERT_EQ(read->model.edges.size(), 9u);
    EXPECT_FALSE(read->model.hasEdge(0, 4));
    EXPECT_TRUE(read->model.hasEdge(4, 1));
}

TEST(ModelFile, TheInterfaceExampleReads) {
    const Result<NamedModel> m = parseModelJson(
        R"({ "id": 0, "name": "body 0", "markers": [[0,0,0],[50,0,0],[0,40,0],[0,0,30]],
             "edges": [[0, 1, 50.0], [0, 2, 40.0]], "s_min": 4 })",
        "example", 64);
    ASSERT_TRUE(m) << m.error().message;
    EXPECT_EQ(m->model.markers_model_mm.size(), 4u);
}

TEST(ModelFile, DefectsGetOneLineErrorsNamingTheFile) {
    const std::string good = R"({ "id": 1, "markers": [[0,0,0],[50,0,0],[0,40,0],[0,0,30]],
                                  "edges": [[0, 1, 50.0]], "s_min": 4 })";
    EXPECT_EQ(errorOf(good), "no error");
    EXPECT_NE(errorOf("{ \"id\": 1,\n \"markers\": [[0,0,0],").find("parse error at line 2"),
              std::string::npos);
    EXPECT_NE(errorOf(R"([1, 2])").find("not a JSON object"), std::string::npos);
    EXPECT_NE(errorOf(R"({ "id": 1, "markers": [], "edges": [] })").find("missing \"s_min\""),
              std::string::npos);
    EXPECT_NE(errorOf(R"({ "id": -1, "markers": [[0,0,0],[1,0,0],[0,1,0]], "edges": [],
                          "s_min": 3 })")
                  .find("\"id\""),
              std::string::npos);
    EXPECT_NE(errorOf(R"({ "id": 1, "markers": [[0,0,0],[1,0],[0,1,0]], "edges": [],
                          "s_min": 3 })")
                  .find("marker 1 is not [x, y, z]"),
              std::string::npos);
    EXPECT_NE(errorOf(R"({ "id": 1, "markers": [[0,0,0],[1,0,0],[0,1,0]],
                          "edges": [[0, 3, 1.0]], "s_min": 3 })")
                  .find("edge 0 joins markers 0 and 3 of 3"),
              std::string::npos);
    EXPECT_NE(errorOf(R"({ "id": 1, "markers": [[0,0,0],[1,0,0],[0,1,0]],
                          "edges": [[1, 1, 1.0]], "s_min": 3 })")
                  .find("edge 0 joins markers 1 and 1"),
              std::string::npos);
    EXPECT_NE(errorOf(R"({ "id": 1, "markers": [[0,0,0],[1,0,0],[0,1,0]], "edges": [],
                          "s_min": 4 })")
                  .find("\"s_min\" is not between 3 and the number of markers"),
              std::string::npos);
    EXPECT_NE(errorOf(good, 3).find("4 markers; at most 3 fit"), std::string::npos);
    // A number no double holds: nlohmann/json throws out_of_range, not parse_error (tests/fuzz).
    EXPECT_NE(errorOf(R"({ "id": 1E999 })").find("number overflow"), std::string::npos);
    for (const std::string& e :
         {errorOf("{"), errorOf(R"({"id": 1})"), errorOf(R"({ "id": 1E999 })")}) {
        EXPECT_EQ(e.rfind("body_9.json: ", 0), 0u) << e;
        EXPECT_EQ(e.find('\n'), std::string::npos) << e;
    }
}

TEST(ModelFile, DirectoryReadsEveryBodyInIdOrderAndRefusesDuplicates) {
    test::TempDir dir;
    MarkerModel a = sampleModel(), b = sampleModel();
    a.id = 7;
    b.id = 2;
    ASSERT_TRUE(writeModelJson(modelPath(dir.path(), a.id), a, "a"));
    ASSERT_TRUE(writeModelJson(modelPath(dir.path(), b.id), b, "b"));
    std::ofstream(dir.path() / "notes.txt") << "not a model\n";
    const Result<std::vector<NamedModel>> models = readModelDirectory(dir.path(), 64);
    ASSERT_TRUE(models) << models.error().message;
    ASSERT_EQ(models->size(), 2u);
    EXPECT_EQ((*models)[0].model.id, 2u);
    EXPECT_EQ((*models)[1].model.id, 7u);

    ASSERT_TRUE(writeModelJson(dir.path() / "body_70.json", a, "copy of a"));
    const Result<std::vector<NamedModel>> duplicate = readModelDirectory(dir.path(), 64);
    ASSERT_FALSE(duplicate);
    EXPECT_NE(duplicate.error().message.find("two models have id 7"), std::string::npos);

    test::TempDir empty;
    EXPECT_FALSE(readModelDirectory(empty.path(), 64));
}

TEST(ModelFile, ADirectoryNamedLikeAModelIsAnErrorNotACrash) {
    // `mkdir -p m/body_0.json` made every reader of the directory abort on an uncaught
    // std::ios_base::failure.
    test::TempDir dir;
    std::filesystem::create_directories(dir.path() / "body_0.json");
    const Result<std::vector<NamedModel>> models = readModelDirectory(dir.path(), 64);
    ASSERT_FALSE(models);
    EXPECT_NE(models.error().message.find("is a directory"), std::string::npos)
        << models.error().message;
    EXPECT_EQ(models.error().message.find('\n'), std::string::npos);
}

} // namespace
} // namespace edgetrack::app
