// rtlab converge: error against run time for one effect, raw accumulation
// against its denoisers, measured on a cached many-sample reference.
#include "commands.hpp"

#include <rtlab/core/error.hpp>
#include <rtlab/core/flip.hpp>
#include <rtlab/core/image.hpp>
#include <rtlab/core/parallel.hpp>
#include <rtlab/core/plot.hpp>
#include <rtlab/core/timer.hpp>
#include <rtlab/denoise/effect_layers.hpp>
#include <rtlab/session/frame_session.hpp>
#include <rtlab/shaders_cpp/effect_table.hpp>

#include <nlohmann/json.hpp>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <iostream>
#include <map>
#include <set>
#include <sstream>

namespace rtlab::app {

void addConvergeCommand(CLI::App& app, ConvergeOptions& o) {
    CLI::App* cmd = app.add_subcommand(
        "converge",
        "Error against run time for one effect: raw accumulation vs its denoisers, on a cached reference (rendered "
        "with a seed derived from --seed)");
    cmd->add_option("--effect", o.effect, shaders::effectNames(shaders::EffectFilter::Denoised, ", "))->required();
    cmd->add_option("--out", o.out, "Output directory (default out/converge/<scene>-<effect>)");
    cmd->add_option("--cache", o.cache, "Directory of cached references")->capture_default_str();
    cmd->add_option("--reference-spp", o.referenceSpp, "Samples per pixel of the reference")
        ->check(CLI::Range(1, 1 << 24))
        ->capture_default_str();
    cmd->add_option("--max-spp", o.maxSpp, "Raw accumulation is measured at 1, 2, 4 ... this many spp")
        ->check(CLI::Range(1, 1 << 16))
        ->capture_default_str();
    cmd->add_option("--denoise-max-spp", o.denoiseMaxSpp, "Denoisers are measured on 1, 2, 4 ... this many spp")
        ->check(CLI::Range(1, 1 << 16))
        ->capture_default_str();
    cmd->add_option("--frames", o.frames, "Temporal history: denoisers also after 1, 2, 4 ... this many 1-spp frames")
        ->check(CLI::Range(1, 4096))
        ->capture_default_str();
    // The render options that shape the effect (the reference uses a different, derived seed).
    addFrameOptions(*cmd, o.frame, session::kUseConverge);
}

namespace {

// The reference's samples must not be the measured runs' samples.
constexpr std::uint32_t kReferenceSeedSalt = 0x9e3779b9u;
// The reference is accumulated in frames of at most this many spp.
constexpr int kReferenceChunkSpp = 64;
// Part of the reference cache's key: 2 since the shadow, AO and reflection
// passes draw their first 2D sample stratified over the screen; 3 since AO
// does so only without contact sampling.
constexpr int kEstimatorVersion = 3;

std::vector<int> powersOfTwoUpTo(int n) {
    std::vector<int> out;
    for (int v = 1; v <= n; v *= 2) out.push_back(v);
    if (out.back() != n) out.push_back(n);
    return out;
}

std::string slug(const std::string& s) {
    std::string out;
    for (const char c : s) out += std::isalnum(static_cast<unsigned char>(c)) ? c : '-';
    return out;
}

// FNV-1a 64 of the text.
std::uint64_t fingerprint(const std::string& text) {
    std::uint64_t h = 1469598103934665603ull;
    for (const unsigned char c : text) h = (h ^ c) * 1099511628211ull;
    return h;
}

// What identifies a scene source for the cache: the name, and for files
// their size and modification time.
std::string sceneIdentity(const std::string& scene) {
    std::string id = scene;
    std::error_code ec;
    if (std::filesystem::is_regular_file(scene, ec)) {
        id += "|" + std::to_string(std::filesystem::file_size(scene, ec));
        id += "|" + std::to_string(std::filesystem::last_write_time(scene, ec).time_since_epoch().count());
    }
    return id;
}

Image rgbImage(int w, int h, const std::vector<vec3>& rgb) {
    Image image(w, h);
    image.addRgbLayer("", rgb);
    return image;
}

struct Measured {
    std::string method;  // "raw", "shadow", "svgf", ...
    std::string kind;    // "spp" (one frame) or "frames" (1 spp per frame, temporal history)
    int spp = 1;
    int frames = 1;
    double ms = 0;  // wall ms of everything that produced this image (all its frames)
    double relMse = 0, psnr = 0, ssim = 0, flip = 0;
    double worstPercentShare = 0;  // ImageDifference::relMseWorstPercentShare
    // Equal-error speed-ups: ms raw needs for this error / ms, against raw
    // samples in one frame (spp) and against accumulated 1-spp frames.
    double rawMsAtEqualError = 0, speedup = 0;
    bool extrapolated = false;
    double rawFramesMsAtEqualError = 0, speedupFrames = 0;
    bool extrapolatedFrames = false;
};

// Milliseconds raw accumulation needs to reach `error`, interpolated
// log-log between the raw points (sorted by spp); beyond the last point
// extrapolated with relMSE ~ 1/ms from it (Monte Carlo's rate).
double rawMsAt(const std::vector<Measured>& raw, double error, bool& extrapolated) {
    extrapolated = false;
    if (raw.empty() || !(error > 0.0)) return 0.0;
    if (error >= raw.front().relMse) return raw.front().ms;
    for (std::size_t i = 1; i < raw.size(); ++i) {
        if (raw[i].relMse > error) continue;
        const double e0 = std::log(raw[i - 1].relMse), e1 = std::log(raw[i].relMse);
        const double m0 = std::log(raw[i - 1].ms), m1 = std::log(raw[i].ms);
        const double t = e1 != e0 ? (std::log(error) - e0) / (e1 - e0) : 1.0;
        return std::exp(m0 + t * (m1 - m0));
    }
    extrapolated = true;
    return raw.back().ms * raw.back().relMse / error;
}

std::string formatDouble(double v, const char* fmt = "%.6g") {
    char buf[64];
    std::snprintf(buf, sizeof buf, fmt, v);
    return buf;
}

// One converge run: its scene and plan (through the frame driver), the
// reference, and the measured rows, step by step.
class ConvergeRun {
public:
    ConvergeRun(const ConvergeOptions& o, session::FrameOptions frame)
        : o_(o), session_(std::move(frame)), w_(o.frame.width), h_(o.frame.height) {}

    // Step: the scene, static (frame time 0), with only the G-buffer and this effect planned.
    void loadScene() {
        session_.load();
        bool planned = false;
        for (const shaders::PlannedPass& pass : session_.advance().plan.passes)
            planned = planned || (shaders::passName(pass.pass) == o_.effect && pass.planned);
        if (!planned)
            throw InputError(o_.frame.scene, "has no " + o_.effect + " to measure (rtlab plan --scene " +
                                                 o_.frame.scene + " says why)");
    }

    // Step: the output and cache directories, once the input is known to be
    // good. A previous run's results are removed first, so that a failed run
    // never leaves an old converge.json beside new images.
    void prepareDirectories(const std::string& out) {
        out_ = out;
        std::error_code ec;
        std::filesystem::create_directories(out_, ec);
        if (ec || !std::filesystem::is_directory(out_)) throw InputError(out_, "cannot create output directory");
        for (const char* name : {"converge.json", "converge.csv", "converge.png"})
            std::filesystem::remove(std::filesystem::path(out_) / name, ec);
        std::filesystem::create_directories(o_.cache, ec);
        if (ec || !std::filesystem::is_directory(o_.cache)) throw InputError(o_.cache, "cannot create cache directory");
    }

    // Step: the reference, from the cache or accumulated now, and the PNGs' exposure.
    void reference();
    // Step: a warm-up render and denoise, not measured (first-touch page
    // faults and lazy initialisation would otherwise land on the first row).
    void warmUp() {
        shaders::FrameHistory none;
        double ms = 0;
        Image warm = render(settingsFor(1, 0, o_.frame.seed), none, ms);
        denoise::EffectLayerDenoiser({o_.effect}).apply(warm);
    }
    void measureRaw();
    void measureRawFrames();
    void measureDenoisers();
    void computeSpeedups();
    void writeResults();
    void printTable() const;

private:
    shaders::RenderSettings settingsFor(int spp, std::uint32_t frame, std::uint32_t seed) const {
        shaders::RenderSettings s = session_.renderSettings();
        s.spp = spp;
        s.frame = frame;
        s.seed = seed;
        return s;
    }
    Image render(const shaders::RenderSettings& s, shaders::FrameHistory& history, double& ms) const {
        const Stopwatch clock;
        shaders::FrameOutput frame = session_.render(s, history);
        ms = clock.elapsedMs();
        return std::move(frame.image);
    }
    void measure(Measured m, const std::vector<vec3>& contribution, const std::string& imageName);
    const Measured& headline() const {
        return *std::find_if(rows_.begin(), rows_.end(), [&](const Measured& m) {
            return m.method == methods_.front().name && m.kind == "spp" && m.spp == 1;
        });
    }

    struct Method {
        std::string name;
        bool forceSvgf;
    };
    const ConvergeOptions& o_;
    session::FrameSession session_;
    const int w_, h_;
    std::string out_;
    std::filesystem::path cacheFile_;
    std::vector<vec3> reference_;
    Image referenceImage_;
    double referenceMs_ = 0;
    bool referenceCached_ = false;
    float exposure_ = 0.f;
    std::vector<Measured> rows_, raw_, rawFrames_;
    std::map<int, Image> rawImages_;  // the denoisers' inputs
    std::vector<int> denoiseSpps_;
    std::vector<Method> methods_;
};

void ConvergeRun::reference() {
    // The key leaves out --ao-contact-samples: it spreads the reference's
    // samples differently, not what they converge to (the estimate is
    // unbiased). kEstimatorVersion: raised when a pass's sampling changes how
    // fast the reference converges (the old cached reference stays unbiased,
    // but a noisier one than a fresh render would be).
    const session::FrameOptions& f = o_.frame;
    std::ostringstream key;
    key << "v" << kEstimatorVersion << "|" << sceneIdentity(f.scene) << "|" << o_.effect << "|" << w_ << "x" << h_
        << "|" << o_.referenceSpp << "|" << f.seed << "|" << formatDouble(f.reflectionRoughness, "%.9g") << "|"
        << formatDouble(f.aoRadius, "%.9g");
    // Every other option converge takes (session::kUseConverge) joins the key
    // where it differs from its default, so that the references cached under
    // version 3 stay valid and a new option can never reuse a reference
    // rendered without it.
    static const std::set<std::string> inKey = {
        "scene", "width", "height", "seed", "reflectionRoughness", "aoRadius", "aoContactSamples", "threads"};
    const nlohmann::json now = f.toJson(session::kUseConverge),
                         defaults = session::FrameOptions{}.toJson(session::kUseConverge);
    for (const auto& [name, value] : now.items())
        if (!inKey.count(name) && value != defaults.at(name)) key << "|" << name << "=" << value.dump();
    char hash[17];
    std::snprintf(hash, sizeof hash, "%016llx", static_cast<unsigned long long>(fingerprint(key.str())));
    cacheFile_ = std::filesystem::path(o_.cache) /
                 (slug(f.scene) + "_" + o_.effect + "_" + std::to_string(w_) + "x" + std::to_string(h_) + "_" +
                  std::to_string(o_.referenceSpp) + "spp_" + std::string(hash) + ".exr");
    if (std::filesystem::exists(cacheFile_)) {
        try {
            const Image cached = readExr(cacheFile_);
            if (cached.width() == w_ && cached.height() == h_ && cached.hasChannel("R")) {
                reference_ = cached.rgbLayer("");
                referenceCached_ = true;
            }
        } catch (const InputError& e) {
            std::cerr << "rtlab: note: ignoring the unreadable cached reference (" << e.what()
                      << "); rendering it again\n";
        }
        if (!referenceCached_)
            std::cerr << "rtlab: note: the cached reference " << cacheFile_.string()
                      << " does not fit; rendering it again\n";
    }
    if (!referenceCached_) {
        std::vector<glm::dvec3> sum(static_cast<std::size_t>(w_) * h_, glm::dvec3(0.0));
        int done = 0;
        std::uint32_t frame = 0;
        const Stopwatch clock;
        while (done < o_.referenceSpp) {
            const int spp = std::min(kReferenceChunkSpp, o_.referenceSpp - done);
            shaders::FrameHistory none;
            double ms = 0;
            const Image image = render(settingsFor(spp, frame++, f.seed ^ kReferenceSeedSalt), none, ms);
            const std::vector<vec3> c = shaders::effectContribution(image, o_.effect);
            for (std::size_t p = 0; p < c.size(); ++p) sum[p] += glm::dvec3(c[p]) * static_cast<double>(spp);
            done += spp;
            const double eta = clock.elapsedMs() / done * (o_.referenceSpp - done) / 1000.0;
            progress("reference: " + std::to_string(done) + "/" + std::to_string(o_.referenceSpp) + " spp, ~" +
                     formatDouble(eta, "%.0f") + " s left");
        }
        referenceMs_ = clock.elapsedMs();
        reference_.resize(sum.size());
        for (std::size_t p = 0; p < sum.size(); ++p) reference_[p] = vec3(sum[p] / static_cast<double>(done));
        writeExr(cacheFile_, rgbImage(w_, h_, reference_), ExrPixelType::Float);
    }
    referenceImage_ = rgbImage(w_, h_, reference_);

    // Display exposure for the PNGs: the reference's 99th-percentile luminance -> 0.8.
    std::vector<float> luminance(reference_.size());
    for (std::size_t p = 0; p < reference_.size(); ++p)
        luminance[p] = 0.2126f * reference_[p].r + 0.7152f * reference_[p].g + 0.0722f * reference_[p].b;
    const float q99 = quantile(luminance.data(), luminance.size(), 0.99);
    exposure_ = q99 > 0.f ? std::log2(0.8f / q99) : 0.f;
    writePng(std::filesystem::path(out_) / "reference.png", referenceImage_, "", exposure_);
}

void ConvergeRun::measure(Measured m, const std::vector<vec3>& contribution, const std::string& imageName) {
    const Image test = rgbImage(w_, h_, contribution);
    const ImageDifference d = compareImages(test, referenceImage_);
    const FlipResult flip = hdrFlip(contribution, reference_, w_, h_);
    m.relMse = d.relMse;
    m.worstPercentShare = d.relMseWorstPercentShare;
    m.psnr = d.psnr;
    m.ssim = d.ssim;
    m.flip = flip.mean;
    if (!imageName.empty()) {
        writePng(std::filesystem::path(out_) / (imageName + ".png"), test, "", exposure_);
        writePng(std::filesystem::path(out_) / ("flip_" + imageName + ".png"), flipErrorImage(flip));
        // The linear values too, for tools (and tests) that compare them exactly.
        writeExr(std::filesystem::path(out_) / (imageName + ".exr"), test, ExrPixelType::Float);
    }
    rows_.push_back(m);
    progress("measured " + m.method + " " + std::to_string(m.kind == "spp" ? m.spp : m.frames) + " " + m.kind);
}

// Step: raw accumulation at 1, 2, 4 ... max spp (frame 0). The fastest of
// three runs counts (up to 16 spp), so that one scheduling hiccup does not
// bend the curve. The denoisers' inputs are the raw images up to --denoise-max-spp.
void ConvergeRun::measureRaw() {
    for (const int spp : powersOfTwoUpTo(o_.maxSpp))
        if (spp <= o_.denoiseMaxSpp) denoiseSpps_.push_back(spp);
    for (const int spp : powersOfTwoUpTo(o_.maxSpp)) {
        double best = 0;
        Image image;
        for (int run = 0; run < (spp <= 16 ? 3 : 1); ++run) {
            shaders::FrameHistory none;
            double ms = 0;
            image = render(settingsFor(spp, 0, o_.frame.seed), none, ms);
            best = run == 0 ? ms : std::min(best, ms);
        }
        measure(Measured{"raw", "spp", spp, 1, best}, shaders::effectContribution(image, o_.effect),
                spp == 1 ? "raw_1spp" : "");
        if (std::find(denoiseSpps_.begin(), denoiseSpps_.end(), spp) != denoiseSpps_.end())
            rawImages_[spp] = std::move(image);
    }
    raw_ = rows_;
}

// Step: raw accumulation of 1-spp frames (frame f uses frame index f): what
// a progressive renderer does; every frame pays the whole pass.
void ConvergeRun::measureRawFrames() {
    std::vector<glm::dvec3> sum(static_cast<std::size_t>(w_) * h_, glm::dvec3(0.0));
    const std::vector<int> checkpoints = powersOfTwoUpTo(o_.maxSpp);
    double totalMs = 0;
    for (int f = 1; f <= o_.maxSpp; ++f) {
        shaders::FrameHistory none;
        double ms = 0;
        const Image image = render(settingsFor(1, static_cast<std::uint32_t>(f - 1), o_.frame.seed), none, ms);
        totalMs += ms;
        const std::vector<vec3> c = shaders::effectContribution(image, o_.effect);
        for (std::size_t p = 0; p < c.size(); ++p) sum[p] += glm::dvec3(c[p]);
        if (std::find(checkpoints.begin(), checkpoints.end(), f) == checkpoints.end()) continue;
        std::vector<vec3> mean(sum.size());
        for (std::size_t p = 0; p < sum.size(); ++p) mean[p] = vec3(sum[p] / static_cast<double>(f));
        measure(Measured{"raw frames", "frames", 1, f, totalMs}, mean, "");
    }
    for (const Measured& m : rows_)
        if (m.method == "raw frames") rawFrames_.push_back(m);
}

// Step: the denoisers: the effect's own stack, and plain SVGF where that differs.
void ConvergeRun::measureDenoisers() {
    {
        Image probe = rawImages_.at(1);
        denoise::EffectLayerDenoiser d({o_.effect});
        std::string stack = "svgf";
        for (const denoise::DenoisedLayer& l : d.apply(probe))
            if (l.stack != denoise::DenoiseStack::Svgf) stack = denoise::stackName(l.stack);
        methods_.push_back({stack, false});
        if (stack != "svgf") methods_.push_back({"svgf", true});
    }
    for (const Method& method : methods_) {
        // One frame, no history, at 1, 2, 4 ... spp. Timed as the fastest of
        // three runs (each on a fresh copy with a fresh denoiser: the same
        // output), so that a scheduling hiccup or the first call's page
        // faults do not count.
        for (const int spp : denoiseSpps_) {
            Image image;
            double denoiseMs = 0;
            for (int run = 0; run < 3; ++run) {
                image = rawImages_.at(spp);
                denoise::EffectLayerDenoiser denoiser({o_.effect}, method.forceSvgf);
                const Stopwatch clock;
                denoiser.apply(image);
                denoiseMs = run == 0 ? clock.elapsedMs() : std::min(denoiseMs, clock.elapsedMs());
            }
            const auto rawRow = std::find_if(raw_.begin(), raw_.end(), [&](const Measured& r) { return r.spp == spp; });
            measure(Measured{method.name, "spp", spp, 1, rawRow->ms + denoiseMs},
                    shaders::effectContribution(image, o_.effect), spp == 1 ? method.name + "_1spp" : "");
        }
        // 1 spp per frame with history (static camera), measured after 1, 2, 4 ... frames.
        denoise::EffectLayerDenoiser denoiser({o_.effect}, method.forceSvgf);
        shaders::FrameHistory history;
        const std::vector<int> checkpoints = powersOfTwoUpTo(o_.frames);
        double totalMs = 0;
        for (int f = 1; f <= o_.frames; ++f) {
            double renderMs = 0;
            Image image = render(settingsFor(1, static_cast<std::uint32_t>(f - 1), o_.frame.seed), history, renderMs);
            const Stopwatch clock;
            denoiser.apply(image);
            totalMs += renderMs + clock.elapsedMs();
            if (std::find(checkpoints.begin(), checkpoints.end(), f) == checkpoints.end()) continue;
            measure(Measured{method.name + " temporal", "frames", 1, f, totalMs},
                    shaders::effectContribution(image, o_.effect),
                    f == o_.frames && f > 1 ? method.name + "_" + std::to_string(f) + "frames" : "");
        }
    }
    progress("");
}

// Step: equal-error speed-ups against raw accumulation.
void ConvergeRun::computeSpeedups() {
    for (Measured& m : rows_) {
        if (m.method == "raw" || m.method == "raw frames") continue;
        m.rawMsAtEqualError = rawMsAt(raw_, m.relMse, m.extrapolated);
        m.speedup = m.ms > 0 ? m.rawMsAtEqualError / m.ms : 0.0;
        m.rawFramesMsAtEqualError = rawMsAt(rawFrames_, m.relMse, m.extrapolatedFrames);
        m.speedupFrames = m.ms > 0 ? m.rawFramesMsAtEqualError / m.ms : 0.0;
    }
}

void ConvergeRun::writeResults() {
    // Step: converge.json, converge.csv, converge.png.
    nlohmann::json j;
    j["scene"] = o_.frame.scene;
    j["effect"] = o_.effect;
    // The render options converge takes (the table's kUseConverge rows), and its own.
    j["settings"] = o_.frame.toJson(session::kUseConverge);
    j["settings"].erase("scene");  // at the top level
    j["settings"].update({{"referenceSpp", o_.referenceSpp},
                          {"maxSpp", o_.maxSpp},
                          {"denoiseMaxSpp", o_.denoiseMaxSpp},
                          {"frames", o_.frames},
                          {"threadsUsed", static_cast<int>(tbb::this_task_arena::max_concurrency())}});
    j["reference"] = {{"file", cacheFile_.string()},
                      {"cached", referenceCached_},
                      {"ms", referenceMs_},
                      {"seed", o_.frame.seed ^ kReferenceSeedSalt}};
    j["plan"] = session_.frame().plan.toJson();
    j["metrics"] = {{"relMse", "mean over pixels and R,G,B of (x - ref)^2 / (ref^2 + 1e-2)"},
                    {"psnr", "10 log10(peak^2 / MSE), peak = max(1, max |ref|)"},
                    {"ssim", "Wang et al. 2004 on Rec.709 luminance clamped to [0, 1]"},
                    {"flip", "mean HDR-FLIP (Andersson et al. 2020, 2021), 67 pixels per degree"},
                    {"ms", "wall milliseconds of every render and denoise that produced the image"},
                    {"speedup",
                     "ms raw (N spp in one frame) needs to reach the same relMSE (log-log "
                     "interpolation; beyond the last raw point relMSE ~ 1/ms) / ms"},
                    {"speedupFrames", "the same against raw accumulation of 1-spp frames"},
                    {"worstPercentShare", "share of the per-pixel relMSE sum held by the worst 1% of pixels"}};
    j["displayExposure"] = exposure_;
    j["rows"] = nlohmann::json::array();
    std::string csv =
        "method,kind,spp,frames,ms,relmse,psnr,ssim,flip,raw_ms_at_equal_error,speedup,extrapolated,"
        "raw_frames_ms_at_equal_error,speedup_frames,extrapolated_frames,worst_percent_share\n";
    for (const Measured& m : rows_) {
        nlohmann::json r = {{"method", m.method},
                            {"kind", m.kind},
                            {"spp", m.spp},
                            {"frames", m.frames},
                            {"ms", m.ms},
                            {"relMse", m.relMse},
                            {"psnr", std::isinf(m.psnr) ? 1e300 : m.psnr},
                            {"ssim", m.ssim},
                            {"flip", m.flip},
                            {"worstPercentShare", m.worstPercentShare}};
        const bool isRaw = m.method == "raw" || m.method == "raw frames";
        if (!isRaw)
            r.update({{"rawMsAtEqualError", m.rawMsAtEqualError},
                      {"speedup", m.speedup},
                      {"extrapolated", m.extrapolated},
                      {"rawFramesMsAtEqualError", m.rawFramesMsAtEqualError},
                      {"speedupFrames", m.speedupFrames},
                      {"extrapolatedFrames", m.extrapolatedFrames}});
        j["rows"].push_back(r);
        csv += m.method + "," + m.kind + "," + std::to_string(m.spp) + "," + std::to_string(m.frames) + "," +
               formatDouble(m.ms) + "," + formatDouble(m.relMse) + "," + formatDouble(m.psnr) + "," +
               formatDouble(m.ssim) + "," + formatDouble(m.flip) + "," + formatDouble(m.rawMsAtEqualError) + "," +
               formatDouble(m.speedup) + "," + (m.extrapolated ? "true" : "false") + "," +
               formatDouble(m.rawFramesMsAtEqualError) + "," + formatDouble(m.speedupFrames) + "," +
               (m.extrapolatedFrames ? "true" : "false") + "," + formatDouble(m.worstPercentShare) + "\n";
    }
    // The headline: the effect's own stack at 1 spp, one frame.
    j["summary"] = {{"stack", methods_.front().name},
                    {"rawRelMse1spp", raw_.front().relMse},
                    {"denoisedRelMse1spp", headline().relMse},
                    {"denoisedWorstPercentShare1spp", headline().worstPercentShare},
                    {"relMseReduction", headline().relMse > 0 ? raw_.front().relMse / headline().relMse : 0.0},
                    {"equalErrorSpeedup", headline().speedup},
                    {"extrapolated", headline().extrapolated},
                    {"equalErrorSpeedupFrames", headline().speedupFrames},
                    {"extrapolatedFrames", headline().extrapolatedFrames}};
    writeTextFileAtomically(std::filesystem::path(out_) / "converge.json", jsonText(j) + "\n");
    writeTextFileAtomically(std::filesystem::path(out_) / "converge.csv", csv);

    std::vector<PlotSeries> series;
    const auto seriesOf = [&](const std::string& method, const std::string& kind, const std::string& label) {
        PlotSeries s{label, {}, {}, false};
        for (const Measured& m : rows_)
            if (m.method == method && m.kind == kind) {
                s.x.push_back(m.ms);
                s.y.push_back(m.relMse);
            }
        if (!s.x.empty()) series.push_back(s);
    };
    seriesOf("raw", "spp", "raw (1, 2, 4 ... spp in one frame)");
    seriesOf("raw frames", "frames", "raw (1, 2, 4 ... 1-spp frames accumulated)");
    for (const Method& method : methods_) {
        seriesOf(method.name, "spp", method.name + " (1 frame, 1, 2 ... spp)");
        seriesOf(method.name + " temporal", "frames", method.name + " (1 spp, after 1, 2, 4 ... frames)");
    }
    PlotOptions plotOptions;
    plotOptions.title =
        o_.effect + " on " + o_.frame.scene + " (" + std::to_string(w_) + "x" + std::to_string(h_) + ")";
    plotOptions.xLabel = "wall milliseconds";
    plotOptions.yLabel = "relMSE";
    const PlotReport plotted = writeLogLogPlot(std::filesystem::path(out_) / "converge.png", series, plotOptions);
    if (plotted.pointsSkipped)
        std::cerr << "rtlab: note: converge.png leaves out " << plotted.pointsSkipped
                  << " points that a log axis cannot show (relMSE or ms <= 0)\n";
}

void ConvergeRun::printTable() const {
    // Step: the table.
    std::printf("%s on %s, %dx%d, reference %d spp%s\n", o_.effect.c_str(), o_.frame.scene.c_str(), w_, h_,
                o_.referenceSpp, referenceCached_ ? " (cached)" : "");
    std::printf("%-22s %6s %6s %10s %11s %8s %7s %7s %10s %10s\n", "method", "spp", "frames", "ms", "relMSE", "PSNR",
                "SSIM", "FLIP", "vs spp", "vs frames");
    const auto speedupText = [](double v, bool extrapolated) {
        return formatDouble(v, "%.1fx") + (extrapolated ? "*" : "");
    };
    for (const Measured& m : rows_) {
        const bool isRaw = m.method == "raw" || m.method == "raw frames";
        std::printf("%-22s %6d %6d %10.1f %11.5g %8.2f %7.4f %7.4f %10s %10s\n", m.method.c_str(), m.spp, m.frames,
                    m.ms, m.relMse, m.psnr, m.ssim, m.flip, isRaw ? "" : speedupText(m.speedup, m.extrapolated).c_str(),
                    isRaw ? "" : speedupText(m.speedupFrames, m.extrapolatedFrames).c_str());
    }
    std::printf(
        "(speed-up = ms raw needs for the same relMSE / ms; vs spp: N spp in one frame, vs frames: N 1-spp "
        "frames accumulated; * = beyond the last raw point, extrapolated with relMSE ~ 1/ms)\n");
    std::printf(
        "%s, 1 spp: relMSE %.4g raw -> %.4g denoised (%.1fx lower); equal-error speed-up %s vs spp, %s vs "
        "frames\n",
        methods_.front().name.c_str(), raw_.front().relMse, headline().relMse,
        headline().relMse > 0 ? raw_.front().relMse / headline().relMse : 0.0,
        speedupText(headline().speedup, headline().extrapolated).c_str(),
        speedupText(headline().speedupFrames, headline().extrapolatedFrames).c_str());
    std::printf("%s, 1 spp: the worst 1%% of pixels hold %.0f%% of the denoised error (%.0f%% of the raw)\n",
                methods_.front().name.c_str(), 100.0 * headline().worstPercentShare,
                100.0 * raw_.front().worstPercentShare);
    // Static-view convergence (issue 16): each method's error with history after
    // 8 frames and after the last, and their ratio (history on a static view
    // keeps lowering the error; `--frames 64` gives the 8-vs-64 figure).
    if (o_.frames > 8) {
        const auto temporalAt = [&](const std::string& method, int frames) -> const Measured* {
            for (const Measured& m : rows_)
                if (m.method == method && m.kind == "frames" && m.frames == frames) return &m;
            return nullptr;
        };
        for (const std::string& method : [&] {
                 std::vector<std::string> names = {"raw frames"};
                 for (const Method& m : methods_) names.push_back(m.name + " temporal");
                 return names;
             }()) {
            const Measured* a = temporalAt(method, 8);
            const Measured* b = temporalAt(method, o_.frames);
            if (!a || !b) continue;
            std::printf("static view, %s: relMSE %.4g after 8 frames, %.4g after %d (%.3f of it)\n", method.c_str(),
                        a->relMse, b->relMse, o_.frames, a->relMse > 0 ? b->relMse / a->relMse : 0.0);
        }
    }
    std::printf("wrote %s/converge.{json,csv,png}\n", out_.c_str());
}

}  // namespace

int runConverge(const ConvergeOptions& o) {
    // Step: options checked before anything is loaded.
    const shaders::EffectRow* row = shaders::effectRowByName(o.effect);
    if (!row || row->denoiseStack.empty())
        throw InputError("--effect", "unknown effect '" + o.effect + "' (known: " +
                                         shaders::effectNames(shaders::EffectFilter::Denoised, ", ") + ")");
    // The G-buffer and this effect only; converge's own denoisers, not --denoise.
    session::FrameOptions frame = o.frame;
    frame.effects = o.effect;
    frame.denoise = "none";
    ConvergeRun run(o, frame);
    run.loadScene();
    run.prepareDirectories(o.out.empty() ? "out/converge/" + slug(o.frame.scene) + "-" + o.effect : o.out);
    run.reference();
    run.warmUp();
    run.measureRaw();
    run.measureRawFrames();
    run.measureDenoisers();
    run.computeSpeedups();
    run.writeResults();
    run.printTable();
    return 0;
}

}  // namespace rtlab::app
