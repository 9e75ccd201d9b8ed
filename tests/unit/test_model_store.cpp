// Tests of the flash model store: round trip, A/B alternation, a power cut at every operation of
// a save, corrupt and empty slots, and payloads that lie about their contents.
#include <random>

#include <gtest/gtest.h>

#include "firmware_app/firmware/model_store.hpp"
#include "hal/sim/devices.hpp"
#include "tests/support/layouts.hpp"

namespace edgetrack::app {
namespace {

constexpr std::size_t kFlashSize = 64 * 1024;
constexpr std::size_t kBlock = 4096;

/// A set of \a count models with co-visibility edges between neighbours; \a seed varies it.
std::vector<NamedModel> modelSet(std::size_t count, unsigned seed) {
    std::vector<NamedModel> set;
    for (std::size_t k = 0; k < count; ++k) {
        const std::vector<Vec3> layout =
            test::irregularLayout(20 + k, seed * 10 + static_cast<unsigned>(k), 10.0);
        NamedModel named{MarkerModel(layout.size()), "body " + std::to_string(k)};
        named.model.id = static_cast<std::uint32_t>(k);
        named.model.sMin = 5;
        for (const Vec3& p : layout)
            named.model.markers_model_mm.push_back(p);
        for (std::size_t i = 0; i < layout.size(); ++i)
            for (std::size_t j = i + 1; j < layout.size(); ++j)
                if ((layout[i] - layout[j]).norm() < 50.0)
                    named.model.edges.push_back(ModelEdge{static_cast<std::uint16_t>(i),
                                                          static_cast<std::uint16_t>(j),
                                                          (layout[i] - layout[j]).norm()});
        set.push_back(std::move(named));
    }
    return set;
}

/// Whether \a a and \a b hold the same models, bit for bit.
bool sameSet(const std::vector<NamedModel>& a, const std::vector<NamedModel>& b) {
    if (a.size() != b.size())
        return false;
    for (std::size_t k = 0; k < a.size(); ++k) {
        const MarkerModel& x = a[k].model;
        const MarkerModel& y = b[k].model;
        if (a[k].name != b[k].name || x.id != y.id || x.sMin != y.sMin ||
            x.markers_model_mm.size() != y.markers_model_mm.size() ||
            x.edges.size() != y.edges.size())
            return false;
        for (std::size_t i = 0; i < x.markers_model_mm.size(); ++i)
            if (x.markers_model_mm[i] != y.markers_model_mm[i])
                return false;
        for (std::size_t e = 0; e < x.edges.size(); ++e)
            if (x.edges[e].from != y.edges[e].from || x.edges[e].to != y.edges[e].to ||
                std::abs(x.edges[e].distance_mm - y.edges[e].distance_mm) > 1e-12)
                return false;
    }
    return true;
}

TEST(ModelStore, SavesAndLoadsAModelSetExactly) {
    sim::SimFlash flash(kFlashSize, kBlock);
    ModelStore store(flash, 128);
    ASSERT_TRUE(store.isValid());
    const std::vector<NamedModel> set = modelSet(3, 1);
    ASSERT_TRUE(store.save(set));
    const Result<StoredModels> loaded = store.load();
    ASSERT_TRUE(loaded) << loaded.error().message;
    EXPECT_TRUE(sameSet(loaded->models, set));
    EXPECT_EQ(loaded->sequence, 1u);
}

TEST(ModelStore, AlternatesSlotsAndLoadsTheNewest) {
    sim::SimFlash flash(kFlashSize, kBlock);
    ModelStore store(flash, 128);
    for (unsigned round = 1; round <= 5; ++round) {
        const std::vector<NamedModel> set = modelSet(1 + round % 3, round);
        ASSERT_TRUE(store.save(set));
        const Result<StoredModels> loaded = store.load();
        ASSERT_TRUE(loaded);
        EXPECT_TRUE(sameSet(loaded->models, set)) << "round " << round;
        EXPECT_EQ(loaded->sequence, round);
        EXPECT_EQ(loaded->slot, static_cast<int>((round - 1) % 2));
    }
    const std::array<SlotReport, 2> slots = store.inspect();
    EXPECT_EQ(slots[0].state, SlotState::Valid);
    EXPECT_EQ(slots[1].state, SlotState::Valid);
}

TEST(ModelStore, APowerCutAtAnyOperationLeavesTheOldOrTheNewSet) {
    const std::vector<NamedModel> oldSet = modelSet(2, 3);
    const std::vector<NamedModel> newSet = modelSet(4, 4);
    // How many erase and write operations one save of the new set takes.
    std::uint64_t operations = 0;
    {
        sim::SimFlash flash(kFlashSize, kBlock);
        ModelStore store(flash, 128);
        ASSERT_TRUE(store.save(oldSet));
        const std::uint64_t before = flash.operations();
        ASSERT_TRUE(store.save(newSet));
        operations = flash.operations() - before;
    }
    ASSERT_GT(operations, 10u) << "the payload should take several page writes";
    RecordProperty("save_operations", std::to_string(operations));
    for (double torn : {0.0, 0.5, 1.0}) {
        int oldLoads = 0, newLoads = 0;
        for (std::uint64_t cut = 0; cut <= operations; ++cut) {
            // Two earlier saves, so that both slots hold a set and the cut hits the older one.
            sim::SimFlash flash(kFlashSize, kBlock);
            ModelStore store(flash, 128);
            ASSERT_TRUE(store.save(modelSet(1, 9)));
            ASSERT_TRUE(store.save(oldSet));
            flash.cutPowerAfter(cut, torn);
            const Status saved = store.save(newSet);
            EXPECT_EQ(static_cast<bool>(saved), cut >= operations) << "cut " << cut;
            flash.restorePower();
            // After the restart, a fresh store on the same flash.
            ModelStore restarted(flash, 128);
            const Result<StoredModels> loaded = restarted.load();
            ASSERT_TRUE(loaded) << "cut " << cut << ", torn " << torn << ": "
                                << loaded.error().message;
            const bool isOld = sameSet(loaded->models, oldSet);
            const bool isNew = sameSet(loaded->models, newSet);
            EXPECT_TRUE(isOld || isNew) << "cut " << cut << ", torn " << torn;
            oldLoads += isOld;
            newLoads += isNew;
            // And the next save after the restart works.
            ASSERT_TRUE(restarted.save(newSet));
            ASSERT_TRUE(restarted.load());
            EXPECT_TRUE(sameSet(restarted.load()->models, newSet));
        }
        // A cut anywhere before the header's write keeps the old set; only a whole save gives
        // the new one (with the header torn at 100%, the last write has landed).
        EXPECT_EQ(newLoads, torn == 1.0 ? 2 : 1) << "torn " << torn;
        EXPECT_EQ(oldLoads + newLoads, static_cast<int>(operations) + 1);
    }
}

TEST(ModelStore, ReportsBothSlotsWhenNeitherLoads) {
    sim::SimFlash flash(kFlashSize, kBlock);
    ModelStore store(flash, 128);
    Result<StoredModels> loaded = store.load();
    ASSERT_FALSE(loaded);
    EXPECT_EQ(loaded.error().message, "no models on flash: slot A empty, slot B empty");

    ASSERT_TRUE(store.save(modelSet(2, 5)));
    ASSERT_TRUE(store.save(modelSet(2, 6)));
    // Decay in slot A's payload and in slot B's header.
    flash.contents()[ModelStore::kHeaderSize + 100] ^= 0x10;
    flash.contents()[kFlashSize / 2 + 9] ^= 0x01;
    loaded = store.load();
    ASSERT_FALSE(loaded);
    EXPECT_NE(loaded.error().message.find("slot A corrupt (payload CRC mismatch)"),
              std::string::npos)
        << loaded.error().message;
    EXPECT_NE(loaded.error().message.find("slot B corrupt (header CRC mismatch"), std::string::npos)
        << loaded.error().message;
    // The board can still save a new set over a corrupt store.
    const std::vector<NamedModel> fresh = modelSet(1, 7);
    ASSERT_TRUE(store.save(fresh));
    ASSERT_TRUE(store.load());
    EXPECT_TRUE(sameSet(store.load()->models, fresh));
}

TEST(ModelStore, FallsBackToTheOlderSlotWhenTheNewerIsCorrupt) {
    sim::SimFlash flash(kFlashSize, kBlock);
    ModelStore store(flash, 128);
    const std::vector<NamedModel> first = modelSet(2, 11);
    ASSERT_TRUE(store.save(first));
    ASSERT_TRUE(store.save(modelSet(3, 12)));
    flash.contents()[kFlashSize / 2 + ModelStore::kHeaderSize + 7] ^= 0x80;
    const Result<StoredModels> loaded = store.load();
    ASSERT_TRUE(loaded) << loaded.error().message;
    EXPECT_TRUE(sameSet(loaded->models, first));
    EXPECT_EQ(loaded->slot, 0);
    // The older set is right to load; saying nothing of the damaged newer one is not.
    EXPECT_EQ(loaded->otherSlotProblem, "slot B corrupt (payload CRC mismatch)");
    // With both slots good, nothing to say.
    ASSERT_TRUE(store.save(modelSet(2, 13)));
    EXPECT_EQ(store.load()->otherSlotProblem, "");
}

TEST(ModelStore, RefusesASetThatDoesNotFitAndKeepsTheOld) {
    sim::SimFlash flash(4 * kBlock, kBlock);
    ModelStore store(flash, 128);
    EXPECT_EQ(store.capacityBytes(), 2 * kBlock - ModelStore::kHeaderSize);
    const std::vector<NamedModel> small = modelSet(1, 13);
    ASSERT_TRUE(store.save(small));
    const Status s = store.save(modelSet(12, 14));
    ASSERT_FALSE(s);
    EXPECT_NE(s.error().message.find("a slot holds"), std::string::npos) << s.error().message;
    EXPECT_TRUE(sameSet(store.load()->models, small));
    sim::SimFlash tiny(kBlock, kBlock);
    EXPECT_FALSE(ModelStore(tiny, 128).isValid());
}

TEST(ModelPayload, RefusesLiesAndNeverReadsPastTheEnd) {
    const std::vector<std::uint8_t> good = encodeModels(modelSet(2, 15));
    ASSERT_TRUE(decodeModels(good, 128));
    EXPECT_FALSE(decodeModels(good, 16)) << "more markers than the tracker holds";
    for (std::size_t length = 0; length < good.size(); length += 7)
        EXPECT_FALSE(decodeModels(std::span(good).first(length), 128)) << "length " << length;
    // Random corruption: every outcome is an error or a well-formed set, never a crash (the
    // sanitizer build checks the reads).
    std::mt19937 random(16);
    for (int trial = 0; trial < 3000; ++trial) {
        std::vector<std::uint8_t> bad = good;
        const int flips = 1 + trial % 4;
        for (int f = 0; f < flips; ++f)
            bad[random() % bad.size()] = static_cast<std::uint8_t>(random());
        const Result<std::vector<NamedModel>> decoded = decodeModels(bad, 128);
        if (!decoded)
            continue;
        for (const NamedModel& m : *decoded)
            for (const ModelEdge& e : m.model.edges) {
                ASSERT_LT(e.to, m.model.markers_model_mm.size());
            }
    }
}

} // namespace
} // namespace edgetrack::app
