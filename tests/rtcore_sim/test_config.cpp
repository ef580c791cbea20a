// The RT-core configuration: defaults, JSON loading, command-line style
// overrides, and bad input reported as InputError naming the key.
#include <rtlab/core/error.hpp>
#include <rtlab/rtcore_sim/config.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include "temp_dir.hpp"

#include <filesystem>
#include <fstream>
#include <string>

using namespace rtlab;
using namespace rtlab::rtcore_sim;
using nlohmann::json;

namespace {

// The InputError message of `fn`, or "" when it does not throw one.
template <class Fn>
std::string inputErrorOf(Fn&& fn) {
    try {
        fn();
    } catch (const InputError& e) {
        return e.what();
    }
    return "";
}

}  // namespace

TEST(RtCoreConfig, DefaultsAndDescriptionsCoverEveryField) {
    const RtCoreConfig config;
    EXPECT_EQ(config.bvh.width, 6u);
    EXPECT_EQ(config.bvh.maxLeafSize, 4u);
    EXPECT_EQ(config.bvh.tlasMaxLeafSize, 1u);
    EXPECT_EQ(config.bvh.buildQuality, BuildQuality::Medium);

    const json dumped = config.toJson();
    const json described = RtCoreConfig::describe();
    ASSERT_TRUE(dumped.contains("bvh"));
    EXPECT_EQ(dumped["bvh"].size(), bvhParamTable().fields().size());
    for (const auto& field : bvhParamTable().fields()) {
        const std::string& name = field.info.name;
        ASSERT_TRUE(dumped["bvh"].contains(name)) << name;
        ASSERT_TRUE(described["bvh"].contains(name)) << name;
        EXPECT_FALSE(field.info.description.empty()) << name;
        EXPECT_EQ(described["bvh"][name]["default"], dumped["bvh"][name]) << name;  // defaults echo Params{}
    }
    EXPECT_EQ(dumped["bvh"]["buildQuality"], "medium");
    EXPECT_EQ(described["bvh"]["width"]["allowed"], json({2, 4, 6, 8}));
    EXPECT_EQ(described["bvh"]["maxLeafSize"]["range"], json({1.0, 32.0}));
}

TEST(RtCoreConfig, JsonOverlaysDefaultsAndRoundTrips) {
    const json input = {
        {"bvh", {{"width", 8}, {"maxLeafSize", 2}, {"buildQuality", "high"}, {"sahTraversalCost", 1.5}}}};
    const RtCoreConfig config = RtCoreConfig::fromJson(input, "test.json");
    EXPECT_EQ(config.bvh.width, 8u);
    EXPECT_EQ(config.bvh.maxLeafSize, 2u);
    EXPECT_EQ(config.bvh.buildQuality, BuildQuality::High);
    EXPECT_FLOAT_EQ(config.bvh.sahTraversalCost, 1.5f);
    EXPECT_EQ(config.bvh.tlasMaxLeafSize, 1u);  // absent: default

    // The dump of a configuration loads back to the same configuration.
    const RtCoreConfig again = RtCoreConfig::fromJson(config.toJson(), "dump");
    EXPECT_EQ(again.toJson(), config.toJson());
}

TEST(RtCoreConfig, LoadsFilesAndNamesThemInErrors) {
    const std::filesystem::path dir = rtlab::test::freshTempDir("rtcore_config_test");
    std::filesystem::create_directories(dir);
    const std::filesystem::path good = dir / "good.json";
    std::ofstream(good) << R"({"bvh": {"width": 2}})";
    EXPECT_EQ(RtCoreConfig::loadFile(good).bvh.width, 2u);

    const std::filesystem::path broken = dir / "broken.json";
    std::ofstream(broken) << R"({"bvh": {"width": )";
    EXPECT_NE(inputErrorOf([&] { RtCoreConfig::loadFile(broken); }).find(broken.string()), std::string::npos);
    EXPECT_NE(inputErrorOf([&] { RtCoreConfig::loadFile(dir / "missing.json"); }).find("missing.json"),
              std::string::npos);
    std::filesystem::remove_all(dir);
}

TEST(RtCoreConfig, SetParsesSectionFieldValue) {
    RtCoreConfig config;
    config.set("bvh.width=8");
    config.set("bvh.buildQuality=low");
    config.set("bvh.refitRebuildThreshold=0");
    config.set("bvh.sahIntersectionCost=2.5");
    EXPECT_EQ(config.bvh.width, 8u);
    EXPECT_EQ(config.bvh.buildQuality, BuildQuality::Low);
    EXPECT_FLOAT_EQ(config.bvh.refitRebuildThreshold, 0.f);
    EXPECT_FLOAT_EQ(config.bvh.sahIntersectionCost, 2.5f);
}

TEST(RtCoreConfig, UnknownKeysAreInputErrorsNamingTheKey) {
    const std::string unknownField = inputErrorOf([] {
        RtCoreConfig::fromJson(json{{"bvh", {{"widht", 4}}}}, "cfg.json");
    });
    EXPECT_NE(unknownField.find("cfg.json"), std::string::npos) << unknownField;
    EXPECT_NE(unknownField.find("bvh.widht"), std::string::npos) << unknownField;
    EXPECT_NE(unknownField.find("width"), std::string::npos) << unknownField;  // lists the known ones

    const std::string unknownSection = inputErrorOf([] {
        RtCoreConfig::fromJson(json{{"cahce", json::object()}}, "cfg.json");
    });
    EXPECT_NE(unknownSection.find("cahce"), std::string::npos) << unknownSection;
    EXPECT_NE(unknownSection.find("bvh"), std::string::npos) << unknownSection;  // lists the known sections
    EXPECT_NE(unknownSection.find("cache"), std::string::npos) << unknownSection;

    RtCoreConfig config;
    const std::string unknownSet = inputErrorOf([&] { config.set("bvh.depth=3"); });
    EXPECT_NE(unknownSet.find("--rtcore-set"), std::string::npos) << unknownSet;
    EXPECT_NE(unknownSet.find("bvh.depth"), std::string::npos) << unknownSet;
    EXPECT_NE(inputErrorOf([&] { config.set("queue.width=3"); }).find("queue"), std::string::npos);
    EXPECT_NE(inputErrorOf([&] { config.set("width=3"); }).find("section.field=value"), std::string::npos);
    EXPECT_NE(inputErrorOf([&] { config.set("bvh.width"); }).find("section.field=value"), std::string::npos);
    EXPECT_NE(inputErrorOf([&] { config.set("bvh.width="); }).find("missing value"), std::string::npos);
    EXPECT_NE(inputErrorOf([] { RtCoreConfig::fromJson(json::array(), "cfg.json"); }).find("object"),
              std::string::npos);
    EXPECT_NE(inputErrorOf([] {
                  RtCoreConfig::fromJson(json{{"bvh", 4}}, "cfg.json");
              }).find("bvh"),
              std::string::npos);
}

TEST(RtCoreConfig, OutOfRangeAndMistypedValuesAreInputErrorsNamingTheKey) {
    const auto errorFor = [](const json& bvh) {
        return inputErrorOf([&] { RtCoreConfig::fromJson(json{{"bvh", bvh}}, "cfg.json"); });
    };
    const std::string width = errorFor({{"width", 5}});
    EXPECT_NE(width.find("bvh.width"), std::string::npos) << width;
    EXPECT_NE(width.find("2, 4, 6, 8"), std::string::npos) << width;
    EXPECT_NE(errorFor({{"maxLeafSize", 0}}).find("bvh.maxLeafSize"), std::string::npos);
    EXPECT_NE(errorFor({{"maxLeafSize", 33}}).find("[1, 32]"), std::string::npos);
    EXPECT_NE(errorFor({{"maxLeafSize", -1}}).find("bvh.maxLeafSize"), std::string::npos);
    EXPECT_NE(errorFor({{"maxLeafSize", 2.5}}).find("unsigned integer"), std::string::npos);
    EXPECT_NE(errorFor({{"width", "8"}}).find("bvh.width"), std::string::npos);
    EXPECT_NE(errorFor({{"buildQuality", "best"}}).find("low, medium, high"), std::string::npos);
    EXPECT_NE(errorFor({{"sahTraversalCost", 0}}).find("bvh.sahTraversalCost"), std::string::npos);
    EXPECT_NE(errorFor({{"refitRebuildThreshold", -1}}).find("bvh.refitRebuildThreshold"), std::string::npos);

    RtCoreConfig config;
    EXPECT_NE(inputErrorOf([&] { config.set("bvh.width=3"); }).find("bvh.width"), std::string::npos);
    EXPECT_NE(inputErrorOf([&] { config.set("bvh.buildQuality=fast"); }).find("bvh.buildQuality"), std::string::npos);
    EXPECT_EQ(config.bvh.width, 6u);  // failed overrides change nothing
}

TEST(RtCoreConfig, EveryTimingSectionHasDescribedDefaultsAndChecksRanges) {
    const json dumped = RtCoreConfig{}.toJson();
    const json described = RtCoreConfig::describe();
    for (const char* section : {"bvh", "core", "scheduler", "traversal", "triangle", "transform", "shader", "stack",
                                "cache", "memory", "gpu", "l2", "dram"}) {
        ASSERT_TRUE(dumped.contains(section)) << section;
        ASSERT_TRUE(described.contains(section)) << section;
        EXPECT_EQ(dumped[section].size(), described[section].size()) << section;
        for (const auto& [field, d] : described[section].items()) {
            EXPECT_FALSE(d["description"].get<std::string>().empty()) << section << "." << field;
            EXPECT_EQ(d["default"], dumped[section][field]) << section << "." << field;
            EXPECT_TRUE(d.contains("range") || d.contains("allowed")) << section << "." << field;
        }
    }
    EXPECT_EQ(dumped.size(), 13u);  // + gpu, l2, dram (issue 14)
    EXPECT_EQ(dumped["core"]["warpWidth"], 32);
    EXPECT_EQ(dumped["scheduler"]["policy"], "fifo");
    EXPECT_EQ(dumped["cache"]["lineBytes"], 64);

    // JSON and overrides reach the new sections; bad values name the key.
    RtCoreConfig config = RtCoreConfig::fromJson(
        json{{"cache", {{"ways", 8}, {"sizeBytes", 65536}}}, {"scheduler", {{"policy", "treelet"}}}}, "cfg.json");
    EXPECT_EQ(config.cache.ways, 8u);
    EXPECT_EQ(config.scheduler.policy, "treelet");
    config.set("memory.latency=350");
    config.set("scheduler.policy=oldestFirst");
    EXPECT_EQ(config.memory.latency, 350u);
    EXPECT_EQ(config.scheduler.policy, "oldestFirst");
    EXPECT_NE(inputErrorOf([&] { config.set("cache.lineBytes=48"); }).find("cache.lineBytes"), std::string::npos);
    EXPECT_NE(inputErrorOf([&] { config.set("core.warpWidth=0"); }).find("[1, 64]"), std::string::npos);
    EXPECT_NE(inputErrorOf([&] { config.set("scheduler.policy=random"); }).find("fifo, oldestFirst, treelet"),
              std::string::npos);
    EXPECT_NE(inputErrorOf([&] { config.set("traversal.speed=2"); }).find("traversal.speed"), std::string::npos);
    // Rules across fields are checked by validate().
    config.set("core.warpWidth=64");
    config.set("core.inputQueueRays=32");
    const std::string queue = inputErrorOf([&] { config.validate("cfg.json"); });
    EXPECT_NE(queue.find("core.inputQueueRays"), std::string::npos) << queue;
    config.set("core.inputQueueRays=64");
    EXPECT_EQ(inputErrorOf([&] { config.validate("cfg.json"); }), "");
}

TEST(RtCoreConfig, ExplicitlySetParametersWithoutEffectAreRefused) {
    // l2.* and dram.* do nothing with the ideal L2 (the single-core defaults).
    RtCoreConfig config;
    config.set("gpu.cores=8");
    config.set("l2.sizeBytes=65536");
    config.set("dram.bytesPerCycle=8");
    try {
        config.checkExplicitKeys("--rtcore-set");
        ADD_FAILURE() << "l2.sizeBytes accepted with l2.mode ideal";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("l2.sizeBytes"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("l2.mode is ideal"), std::string::npos) << e.what();
    }
    config.set("l2.mode=cache");
    EXPECT_NO_THROW(config.checkExplicitKeys("--rtcore-set"));
    // Launch parameters in tile mode; the dispatch rule on one core; treelet sizes of fifo.
    for (const auto& [setting, inert] : std::vector<std::pair<std::string, std::string>>{
             {"gpu.launch=tile", "gpu.residentWarps=4"},
             {"gpu.launch=tile", "shader.nextTraceLatency=10"},
             {"gpu.cores=1", "gpu.dispatch=contiguous"},
             {"scheduler.policy=fifo", "scheduler.treeletBytes=8192"},
             {"scheduler.policy=treelet", "scheduler.prefetchBytes=512"}}) {
        RtCoreConfig c;
        c.set(setting);
        c.set(inert);
        EXPECT_THROW(c.checkExplicitKeys("x"), InputError) << setting << " " << inert;
    }
    // The L2's service order on one core (its port delivers in the order made).
    {
        RtCoreConfig c;
        c.set("l2.mode=cache");
        c.set("l2.serviceOrder=arrival");
        c.set("gpu.cores=2");
        EXPECT_NO_THROW(c.checkExplicitKeys("x"));
        c.set("gpu.cores=1");
        try {
            c.checkExplicitKeys("x");
            ADD_FAILURE() << "l2.serviceOrder accepted on one core";
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find("l2.serviceOrder: has no effect here: gpu.cores is 1"),
                      std::string::npos)
                << e.what();
        }
    }
    // Inherited values are never checked: a preset's or file's l2 fields with l2 ideal are fine.
    const RtCoreConfig file = RtCoreConfig::fromJson(nlohmann::json::parse(R"({"l2": {"sizeBytes": 65536}})"), "f");
    EXPECT_TRUE(file.explicitKeys().empty());
    EXPECT_NO_THROW(file.checkExplicitKeys("f"));
}

TEST(RtCoreConfig, PresetsLoadByNameValidateAndDocumentEveryNumber) {
    const std::vector<std::string> names = rtcorePresetNames();
    for (const char* expected : {"single-core", "rtx2060-like", "h100-like"})
        EXPECT_NE(std::find(names.begin(), names.end(), expected), names.end()) << expected;
    EXPECT_EQ(RtCoreConfig::load("").toJson(), RtCoreConfig::load(kDefaultRtCorePreset).toJson());
    EXPECT_EQ(RtCoreConfig::load("single-core").toJson(), RtCoreConfig{}.toJson());  // the hand-computed tests' model
    for (const std::string& name : names) {
        SCOPED_TRACE(name);
        const RtCoreConfig c = RtCoreConfig::load(name);
        EXPECT_NO_THROW(c.validate(name));
        const nlohmann::json j = nlohmann::json::parse(rtcorePresetText(name));
        ASSERT_TRUE(j.contains("description"));
        ASSERT_TRUE(j.contains("sources"));
        // Every number the preset sets names its source.
        for (const auto& [section, fields] : j.items()) {
            if (section == "description" || section == "sources") continue;
            for (const auto& [field, value] : fields.items())
                EXPECT_TRUE(j["sources"].contains(section + "." + field) || j["sources"].contains(section + ".*"))
                    << section << "." << field << " has no source";
        }
    }
    const RtCoreConfig rtx = RtCoreConfig::load("rtx2060-like");
    EXPECT_EQ(rtx.gpu.cores, 30u);
    EXPECT_EQ(rtx.l2.mode, L2Mode::Cache);
    EXPECT_EQ(rtx.gpu.launch, LaunchMode::Launch);
    EXPECT_THROW(RtCoreConfig::load("no-such-preset"), InputError);
}
