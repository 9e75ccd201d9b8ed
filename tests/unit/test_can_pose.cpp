// Tests of the CAN pose frames, decoded through deploy/edgetrack.dbc as a CAN tool would.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "firmware_app/firmware/can_pose.hpp"
#include "tests/support/dbc.hpp"

namespace edgetrack::app {
namespace {

using test::DbcMessage;
using test::decode;
using test::readDbc;
using test::readText;

const std::filesystem::path kDbc = test::deployedDbc();

CanPose randomPose(std::mt19937& random, std::uint32_t body) {
    std::uniform_real_distribution<double> position(-1500.0, 1500.0);
    std::uniform_real_distribution<double> component(-1.0, 1.0);
    CanPose pose;
    pose.body = body;
    pose.found = true;
    pose.frame = random() % 10000000u;
    pose.T_rig_from_model.translation_mm =
        Vec3(position(random), position(random), position(random));
    pose.T_rig_from_model.rotation = quaternionFromWxyz(component(random), component(random),
                                                        component(random), component(random));
    pose.markers = static_cast<std::uint32_t>(random() % 40u);
    pose.rms_mm = 0.001 * static_cast<double>(random() % 900u);
    pose.latency_s = 0.000001 * static_cast<double>(random() % 20000u);
    return pose;
}

TEST(CanPose, DeployedDbcIsTheOneTheEncoderFollows) {
    const std::string expected = poseDbc(CanPoseLayout{});
    const std::string deployed = readText(kDbc);
    if (deployed != expected) {
        const std::filesystem::path fresh = std::filesystem::current_path() / "edgetrack.dbc";
        std::ofstream(fresh) << expected;
        FAIL() << kDbc << " differs from the encoder's layout; the current one is in " << fresh;
    }
}

TEST(CanPose, ClassicFramesDecodeThroughTheDbc) {
    const auto dbc = readDbc(readText(kDbc));
    ASSERT_EQ(dbc.size(), 64u) << "16 bodies, three classic frames and one FD frame each";
    std::mt19937 random(1);
    for (int trial = 0; trial < 200; ++trial) {
        const CanPose pose = randomPose(random, static_cast<std::uint32_t>(trial % 16));
        const std::array<double, 4> q = wxyzFromQuaternion(pose.T_rig_from_model.rotation);
        const auto frames = encodeClassicPose(pose, CanPoseLayout{});
        std::map<std::string, double> all;
        for (const hal::CanFrame& frame : frames) {
            ASSERT_TRUE(dbc.contains(frame.id)) << "id " << frame.id;
            const DbcMessage& message = dbc.at(frame.id);
            EXPECT_FALSE(frame.fd);
            EXPECT_FALSE(message.fd);
            EXPECT_EQ(frame.length, message.length);
            EXPECT_NE(message.name.find("BODY" + std::to_string(pose.body) + "_"),
                      std::string::npos);
            const auto values = decode(message, frame);
            EXPECT_EQ(values.at("Counter"), static_cast<double>(pose.frame % 16));
            all.insert(values.begin(), values.end());
        }
        const Vec3& t = pose.T_rig_from_model.translation_mm;
        EXPECT_NEAR(all.at("PositionX"), t.x(), 0.0051);
        EXPECT_NEAR(all.at("PositionY"), t.y(), 0.0051);
        EXPECT_NEAR(all.at("PositionZ"), t.z(), 0.0051);
        EXPECT_NEAR(all.at("QuatW"), q[0], 3.1e-5);
        EXPECT_NEAR(all.at("QuatX"), q[1], 3.1e-5);
        EXPECT_NEAR(all.at("QuatY"), q[2], 3.1e-5);
        EXPECT_NEAR(all.at("QuatZ"), q[3], 3.1e-5);
        EXPECT_EQ(all.at("Found"), 1.0);
        EXPECT_EQ(all.at("Markers"), static_cast<double>(pose.markers));
        EXPECT_EQ(all.at("FrameNumber"), static_cast<double>(pose.frame));
        EXPECT_NEAR(all.at("Latency"), pose.latency_s * 1e6, 0.5);
    }
}

TEST(CanPose, FdFrameDecodesThroughTheDbc) {
    const auto dbc = readDbc(readText(kDbc));
    std::mt19937 random(2);
    for (int trial = 0; trial < 200; ++trial) {
        const CanPose pose = randomPose(random, static_cast<std::uint32_t>(trial % 16));
        const std::array<double, 4> q = wxyzFromQuaternion(pose.T_rig_from_model.rotation);
        const hal::CanFrame frame = encodeFdPose(pose, CanPoseLayout{});
        ASSERT_TRUE(dbc.contains(frame.id));
        const DbcMessage& message = dbc.at(frame.id);
        EXPECT_TRUE(frame.fd);
        EXPECT_TRUE(message.fd);
        EXPECT_EQ(frame.length, message.length);
        EXPECT_TRUE(hal::isValidCanLength(frame.length, true));
        const auto values = decode(message, frame);
        const Vec3& t = pose.T_rig_from_model.translation_mm;
        EXPECT_NEAR(values.at("PositionX"), t.x(), 0.00051);
        EXPECT_NEAR(values.at("PositionY"), t.y(), 0.00051);
        EXPECT_NEAR(values.at("PositionZ"), t.z(), 0.00051);
        EXPECT_NEAR(values.at("QuatW"), q[0], 1.6e-5);
        EXPECT_NEAR(values.at("QuatX"), q[1], 1.6e-5);
        EXPECT_NEAR(values.at("QuatY"), q[2], 1.6e-5);
        EXPECT_NEAR(values.at("QuatZ"), q[3], 1.6e-5);
        EXPECT_EQ(values.at("FrameNumber"), static_cast<double>(pose.frame));
        EXPECT_EQ(values.at("Markers"), static_cast<double>(pose.markers));
        EXPECT_NEAR(values.at("Rms"), pose.rms_mm, 0.00051);
        EXPECT_NEAR(values.at("Latency"), pose.latency_s * 1e6, 0.5);
        EXPECT_EQ(values.at("Found"), 1.0);
    }
}

TEST(CanPose, ClampsRatherThanWrapsAndSaysWhenNotFound) {
    const auto dbc = readDbc(readText(kDbc));
    CanPose far;
    far.found = true;
    far.T_rig_from_model.translation_mm = Vec3(9000.0, -9000.0, 5242.9);
    const auto frames = encodeClassicPose(far, CanPoseLayout{});
    const auto values = decode(dbc.at(frames[0].id), frames[0]);
    EXPECT_NEAR(values.at("PositionX"), 5242.87, 1e-9);
    EXPECT_NEAR(values.at("PositionY"), -5242.88, 1e-9);
    EXPECT_NEAR(values.at("PositionZ"), 5242.87, 1e-9);

    CanPose lost;
    lost.body = 5;
    lost.frame = 77;
    const hal::CanFrame fd = encodeFdPose(lost, CanPoseLayout{});
    const auto fdValues = decode(dbc.at(fd.id), fd);
    EXPECT_EQ(fdValues.at("Found"), 0.0);
    EXPECT_EQ(fdValues.at("FrameNumber"), 77.0);
}

} // namespace
} // namespace edgetrack::app
