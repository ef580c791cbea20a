#pragma once
// The RT-core model's parameters (docs/rtcore-model.md): one typed struct per
// concern, each field with a default, a one-line description and a valid
// range, gem5 style. A ParamTable describes the fields of one struct; the
// RtCoreConfig groups the structs into named sections ("bvh", later the
// units), loads them from JSON, applies "section.field=value" overrides and
// dumps the resolved values (echoed into stats files).
//
// Bad input (unknown keys, wrong types, out-of-range values) throws
// rtlab::InputError naming the key, e.g. "cfg.json: bvh.width: must be one
// of 2, 4, 6, 8 (got 5)".
#include <rtlab/core/error.hpp>

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace rtlab::rtcore_sim {

// ---------------------------------------------------------------------------
// Generic field descriptions.

enum class ParamKind : std::uint8_t { Unsigned, Real, Boolean, Choice };

// What the configuration knows about one parameter: enough to validate a
// value, print help and echo the default.
struct ParamInfo {
    std::string name;         // field name inside its section, e.g. "width"
    std::string description;  // one line
    ParamKind kind = ParamKind::Unsigned;
    nlohmann::json defaultValue;
    double min = 0.0;  // inclusive range (Unsigned, Real)
    double max = 0.0;
    std::vector<nlohmann::json> allowed;  // when non-empty, the only accepted values
};

// Checks `value` against `info` and returns it in canonical form; throws
// InputError(where, "<key>: <problem>") otherwise.
nlohmann::json checkParamValue(const ParamInfo& info, const nlohmann::json& value, const std::string& where,
                               const std::string& key);

// One parameter with typed access to its member of Params.
template <class Params>
struct ParamField {
    ParamInfo info;
    std::function<nlohmann::json(const Params&)> read;
    std::function<void(Params&, const nlohmann::json&)> write;  // value already passed checkParamValue
};

// The fields of one parameter struct. Defaults are read from Params{}.
template <class Params>
class ParamTable {
public:
    ParamTable& addUnsigned(std::string name, std::uint32_t Params::*member, std::string description, std::uint32_t min,
                            std::uint32_t max) {
        ParamInfo info{std::move(name), std::move(description), ParamKind::Unsigned, {}, double(min), double(max), {}};
        return add(std::move(info), member);
    }
    ParamTable& addUnsignedOneOf(std::string name, std::uint32_t Params::*member, std::string description,
                                 const std::vector<std::uint32_t>& allowed) {
        ParamInfo info{std::move(name), std::move(description), ParamKind::Unsigned, {}, 0.0, 0.0, {}};
        for (std::uint32_t v : allowed) info.allowed.emplace_back(v);
        return add(std::move(info), member);
    }
    ParamTable& addReal(std::string name, float Params::*member, std::string description, float min, float max) {
        ParamInfo info{std::move(name), std::move(description), ParamKind::Real, {}, double(min), double(max), {}};
        return add(std::move(info), member);
    }
    ParamTable& addBoolean(std::string name, bool Params::*member, std::string description) {
        ParamInfo info{std::move(name), std::move(description), ParamKind::Boolean, {}, 0.0, 0.0, {}};
        return add(std::move(info), member);
    }
    template <class Enum>
    ParamTable& addChoice(std::string name, Enum Params::*member, std::string description,
                          std::vector<std::pair<std::string, Enum>> choices) {
        ParamField<Params> field;
        field.info = ParamInfo{std::move(name), std::move(description), ParamKind::Choice, {}, 0.0, 0.0, {}};
        for (const auto& [label, value] : choices) field.info.allowed.emplace_back(label);
        field.read = [member, choices](const Params& p) -> nlohmann::json {
            for (const auto& [label, value] : choices)
                if (p.*member == value) return label;
            return nullptr;
        };
        field.write = [member, choices](Params& p, const nlohmann::json& v) {
            for (const auto& [label, value] : choices)
                if (v == label) p.*member = value;
        };
        field.info.defaultValue = field.read(Params{});
        fields_.push_back(std::move(field));
        return *this;
    }

    const std::vector<ParamField<Params>>& fields() const { return fields_; }
    const ParamField<Params>* find(std::string_view name) const {
        for (const ParamField<Params>& f : fields_)
            if (f.info.name == name) return &f;
        return nullptr;
    }

private:
    template <class T>
    ParamTable& add(ParamInfo info, T Params::*member) {
        ParamField<Params> field;
        field.info = std::move(info);
        field.read = [member](const Params& p) -> nlohmann::json { return p.*member; };
        field.write = [member](Params& p, const nlohmann::json& v) { p.*member = v.get<T>(); };
        field.info.defaultValue = field.read(Params{});
        fields_.push_back(std::move(field));
        return *this;
    }

    std::vector<ParamField<Params>> fields_;
};

// ---------------------------------------------------------------------------
// Parameter structs.

// Embree builder quality: low = Morton build, medium = binned SAH,
// high = binned SAH with spatial splits (SBVH; a triangle may then be
// referenced from several leaves).
enum class BuildQuality : std::uint8_t { Low, Medium, High };

// The bounding volume hierarchy the model traverses (section "bvh").
struct BvhParams {
    std::uint32_t width = 6;             // children per internal node
    std::uint32_t maxLeafSize = 4;       // triangles per BLAS leaf at most
    std::uint32_t tlasMaxLeafSize = 1;   // instances per TLAS leaf at most
    BuildQuality buildQuality = BuildQuality::Medium;
    float sahTraversalCost = 1.f;        // builder's cost of one node step (relative)
    float sahIntersectionCost = 1.f;     // builder's cost of one primitive test (relative)
    float refitRebuildThreshold = 2.f;   // rebuild a refit BLAS once its SAH cost exceeds this multiple of its build cost
};
const ParamTable<BvhParams>& bvhParamTable();

// ---------------------------------------------------------------------------
// The whole configuration.

struct RtCoreConfig {
    BvhParams bvh;
    // Later units add their parameter structs here and one section line in
    // config.cpp (forEachSection).

    // A JSON object {"section": {"field": value, ...}, ...}; absent fields
    // keep their defaults. `where` names the source in error messages.
    static RtCoreConfig fromJson(const nlohmann::json& json, const std::string& where);
    // Reads and parses a JSON file (InputError names the file).
    static RtCoreConfig loadFile(const std::filesystem::path& path);

    // Overlays the fields present in `json` onto this configuration.
    void applyJson(const nlohmann::json& json, const std::string& where);
    // One override "section.field=value"; value is JSON (8, 1.5, true) or a
    // bare word for choices (bvh.buildQuality=high).
    void set(const std::string& assignment, const std::string& where = "--rtcore-set");

    // The resolved configuration, every field present.
    nlohmann::json toJson() const;
    // Every parameter: description, default, range or allowed values.
    static nlohmann::json describe();
};

std::string toString(BuildQuality quality);

}  // namespace rtlab::rtcore_sim
