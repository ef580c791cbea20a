// The frame options' table: one row per option, each reaching the command
// line, studies and stats.json; validation and the command-line form.
#include <rtlab/core/error.hpp>
#include <rtlab/session/frame_options.hpp>
#include <rtlab/shaders_cpp/effect_table.hpp>

#include <gtest/gtest.h>

#include <set>

namespace rtlab::session {
namespace {

TEST(FrameOptions, EveryRowHasAUniqueFlagKeyAndHelp) {
    std::set<std::string> flags, keys;
    for (const FrameOptionField& f : frameOptionFields()) {
        EXPECT_TRUE(flags.insert(f.flag).second) << f.flag;
        EXPECT_TRUE(keys.insert(f.key).second) << f.key;
        EXPECT_EQ(f.flag.rfind("--", 0), 0u) << f.flag;
        EXPECT_FALSE(f.help.empty()) << f.flag;
        EXPECT_NE(f.uses, 0u) << f.flag;
        EXPECT_EQ(frameOptionByKey(f.key), &f);
    }
    EXPECT_EQ(frameOptionByKey("noSuchOption"), nullptr);
}

TEST(FrameOptions, HelpNamesEveryListableAndDenoisedEffect) {
    const std::string effects = frameOptionByKey("effects")->help, denoise = frameOptionByKey("denoise")->help;
    for (const shaders::EffectRow& row : shaders::effectTable()) {
        if (row.listable) {
            EXPECT_NE(effects.find(std::string(row.name)), std::string::npos) << row.name;
        }
        if (!row.denoiseStack.empty()) {
            EXPECT_NE(denoise.find(std::string(row.name)), std::string::npos) << row.name;
        }
    }
}

TEST(FrameOptions, ArgumentsCarryOnlyWhatDiffersFromTheDefaults) {
    FrameOptions o;
    EXPECT_TRUE(o.toArgs(kUseRender).empty());
    o.width = 32;
    o.maxTranslucencyDepth = 3;
    o.aoRadius = 0.25f;
    o.verify = true;
    o.backend = "rtcore";
    o.rtcoreSet = {"gpu.cores=2", "cache.sizeBytes=4096"};
    const std::vector<std::string> expected = {"--width",
                                               "32",
                                               "--backend",
                                               "rtcore",
                                               "--rtcore-set",
                                               "gpu.cores=2",
                                               "--rtcore-set",
                                               "cache.sizeBytes=4096",
                                               "--verify",
                                               "--ao-radius",
                                               "0.25",
                                               "--max-translucency-depth",
                                               "3"};
    EXPECT_EQ(o.toArgs(kUseRender), expected);
    // Only the options of the asked-for command.
    for (const std::string& a : o.toArgs(kUsePlan)) EXPECT_NE(a, "--width");
}

TEST(FrameOptions, StudyJsonRoundTrips) {
    FrameOptions o;
    o.width = 8;
    o.seed = 4000000000u;
    o.reflectionRoughness = 0.7f;
    o.gi = "ddgi";
    o.maxDepth = 0;
    o.rtcoreConfig = "gpu.json";  // a study names a file or leaves the key out ("" is refused)
    FrameOptions back;
    const nlohmann::json json = o.toJson(kUseStudy);
    for (const auto& [key, value] : json.items()) back.setFromJson(key, value, "s.json", "render.");
    EXPECT_EQ(back.toJson(kUseStudy), o.toJson(kUseStudy));
    EXPECT_EQ(back.seed, 4000000000u);
    EXPECT_EQ(back.reflectionRoughness, 0.7f);
}

TEST(FrameOptions, JsonValuesAreCheckedLikeTheCommandLine) {
    FrameOptions o;
    const auto message = [&](const char* key, const nlohmann::json& v) {
        try {
            o.setFromJson(key, v, "s.json", "render.");
        } catch (const InputError& e) {
            return std::string(e.what());
        }
        return std::string("no error");
    };
    EXPECT_EQ(message("width", 0), "s.json: render.width: must be an integer in 1..16384 (got 0)");
    EXPECT_EQ(message("seed", -1), "s.json: render.seed: must be an integer in 0..4294967295 (got -1)");
    EXPECT_EQ(message("gi", "photons"), "s.json: render.gi: must be one of path, ddgi (got \"photons\")");
    EXPECT_EQ(message("aoRadius", "far"), "s.json: render.aoRadius: must be a number in 0..1e+30 (got \"far\")");
    EXPECT_EQ(message("effects", ""), "s.json: render.effects: must be a non-empty string (got \"\")");
    EXPECT_EQ(message("verify", 1), "s.json: render.verify: must be true or false (got 1)");
    EXPECT_EQ(message("glitter", 1), "s.json: render.glitter: unknown option");
}

TEST(FrameOptions, ValidateChecksRangesAndRtCoreOnlyOptions) {
    FrameOptions o;
    EXPECT_NO_THROW(o.validate());
    o.spp = 0;
    EXPECT_THROW(o.validate(), InputError);
    o.spp = 1;
    o.aoRadius = 1e30f;  // the top of its range, as a float (the command line has always taken it)
    EXPECT_NO_THROW(o.validate());
    o.rtcoreSet = {"gpu.cores=2"};
    try {
        o.validate();
        FAIL() << "--rtcore-set without --backend rtcore accepted";
    } catch (const InputError& e) {
        EXPECT_STREQ(e.what(), "--rtcore-set: only applies to --backend rtcore");
    }
    o.backend = "rtcore";
    EXPECT_NO_THROW(o.validate());
    EXPECT_EQ(o.rtcoreConfiguration().toJson(), [] {
        rtcore_sim::RtCoreConfig c = rtcore_sim::RtCoreConfig::load(rtcore_sim::kDefaultRtCorePreset);
        c.set("gpu.cores=2");
        return c.toJson();
    }());
    o.effects = "ao,glitter";
    EXPECT_THROW(o.planOptions(), InputError);
    o.denoise = "ao,pathtrace";  // pathtrace has no denoiser
    EXPECT_THROW(o.denoiseList(), InputError);
    o.denoise = "gi,ao";
    EXPECT_EQ(o.denoiseList(), (std::vector<std::string>{"gi", "ao"}));
}

}  // namespace
}  // namespace rtlab::session
