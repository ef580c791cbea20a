// `rtlab report` opened in headless Chromium (Debian's chromium, installed by
// scripts/install-deps.sh): the page loads without console errors, its DOM
// holds the summary, the plots as inline SVG with a <title> per point and the
// table, and its screenshot is not blank and shows the plots' coloured
// lines; the PDF figures open in poppler (pdftoppm) into non-blank pages
// with the font embedded. Its own executable, ctest label "chromium"
// (ctest -L chromium runs it alone; -LE chromium leaves it out).
#define STB_IMAGE_IMPLEMENTATION
#define STB_IMAGE_STATIC
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wunused-function"
#include <stb_image.h>
#pragma GCC diagnostic pop

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include "../apps/cli_test_util.hpp"

#include <fstream>
#include <set>
#include <string>
#include <sys/wait.h>
#include <unistd.h>

namespace fs = std::filesystem;

namespace {

using Result = rtlab::test::CliRun;
const auto run = rtlab::test::runCommand;

std::string chromium() {
    for (const char* c : {"/usr/bin/chromium", "/usr/bin/chromium-browser"})
        if (fs::exists(c)) return c;
    return {};
}

std::size_t count(const std::string& text, const std::string& what) {
    std::size_t n = 0;
    for (std::size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
    return n;
}

}  // namespace

TEST(ReportInChromium, LoadsWithoutConsoleErrorsAndShowsPlots) {
    const std::string browser = chromium();
    if (browser.empty()) GTEST_SKIP() << "no chromium (scripts/install-deps.sh installs it)";
    const fs::path dir = rtlab::test::freshDir("chromium_report");
    fs::create_directories(dir);
    std::ofstream(dir / "study.json") << R"({"workloads": ["builtin:cornell", "builtin:terrain?triangles=2000"],
        "render": {"width": 24, "height": 24, "effects": "gbuffer"},
        "grid": {"cache.sizeBytes": [2048, 32768], "scheduler.policy": ["fifo", "treelet"]}})";
    const fs::path out = dir / "sweep";
    const Result sweep = run(std::string(RTLAB_CLI) + " sweep " + (dir / "study.json").string() + " --out " +
                             out.string() + " --jobs 2");
    ASSERT_EQ(sweep.exitCode, 0) << sweep.out;
    const Result report = run(std::string(RTLAB_CLI) + " report " + out.string());
    ASSERT_EQ(report.exitCode, 0) << report.out;
    const fs::path html = out / "report.html";

    // Headless, no GPU, a private profile; as root Chromium needs --no-sandbox.
    std::string flags =
        " --headless --disable-gpu --hide-scrollbars --no-first-run --mute-audio"
        " --user-data-dir=" +
        (dir / "profile").string() +
        " --window-size=1100,1500 --virtual-time-budget=3000 --enable-logging=stderr --v=0";
    if (geteuid() == 0) flags += " --no-sandbox";
    const std::string url = " file://" + fs::absolute(html).string();

    const fs::path png = dir / "screenshot.png";
    const Result shot = run("timeout 60 " + browser + flags + " --screenshot=" + png.string() + url);
    ASSERT_EQ(shot.exitCode, 0) << shot.out;
    // Console messages and script errors are logged as CONSOLE(...) / Uncaught lines.
    EXPECT_EQ(shot.out.find("CONSOLE"), std::string::npos) << shot.out;
    EXPECT_EQ(shot.out.find("Uncaught"), std::string::npos) << shot.out;
    EXPECT_EQ(shot.out.find("Failed to load resource"), std::string::npos) << shot.out;

    int w = 0, h = 0, channels = 0;
    unsigned char* pixels = stbi_load(png.c_str(), &w, &h, &channels, 3);
    ASSERT_NE(pixels, nullptr) << "no screenshot: " << shot.out;
    std::size_t nonWhite = 0, coloured = 0;
    std::set<unsigned> colours;
    for (int i = 0; i < w * h; ++i) {
        const unsigned char* p = pixels + 3 * i;
        const int lo = std::min({p[0], p[1], p[2]}), hi = std::max({p[0], p[1], p[2]});
        nonWhite += lo < 235;
        coloured += hi - lo > 80;  // the plots' series colours (text and tables are grey)
        colours.insert(unsigned(p[0]) << 16 | unsigned(p[1]) << 8 | p[2]);
    }
    stbi_image_free(pixels);
    EXPECT_EQ(w, 1100);
    EXPECT_GT(nonWhite, std::size_t(w) * h / 100) << "blank page";
    EXPECT_GT(colours.size(), 16u) << "a page of one or two colours";
    EXPECT_GT(coloured, 200u) << "no plot visible (images not decoded?)";

    // The parsed document: every plot inline as SVG, a point's <title> with
    // its whole configuration, the summary first, the points table.
    const Result dom = run("timeout 60 " + browser + flags + " --dump-dom" + url);
    ASSERT_EQ(dom.exitCode, 0) << dom.out;
    EXPECT_EQ(dom.out.find("CONSOLE"), std::string::npos) << dom.out;
    std::size_t svgFiles = 0, pdfFiles = 0, csvFiles = 0;
    for (const auto& e : fs::directory_iterator(out / "plots")) {
        svgFiles += e.path().extension() == ".svg";
        pdfFiles += e.path().extension() == ".pdf";
        csvFiles += e.path().extension() == ".csv";
    }
    EXPECT_EQ(count(dom.out, "<svg "), svgFiles);
    EXPECT_GE(svgFiles, 4u);
    EXPECT_EQ(pdfFiles, svgFiles);
    EXPECT_EQ(csvFiles, svgFiles);
    EXPECT_EQ(count(dom.out, "<img "), 0u) << "plots are inline SVG, not images";
    EXPECT_NE(dom.out.find("<title>p0000: builtin:cornell; cache.sizeBytes=2048, scheduler.policy=fifo; cycles = "),
              std::string::npos);
    const std::size_t summary = dom.out.find("<h2 id=\"summary\">Summary</h2>");
    ASSERT_NE(summary, std::string::npos);
    EXPECT_LT(summary, dom.out.find("<h2>Plots</h2>")) << "the summary comes first";
    EXPECT_EQ(count(dom.out, "<td class=\"l best\">"), 2u) << "a best configuration per workload";
    EXPECT_NE(dom.out.find("<a href=\"plots/cycles-vs-cache.sizeBytes.csv\">"), std::string::npos);
    EXPECT_TRUE(fs::exists(out / "summary.json"));
    EXPECT_EQ(count(dom.out, "<tr><td class=\"l\">p00"), 8u);

    // The PDFs: each opens in poppler (pdftoppm) into a page that is not blank.
    ASSERT_TRUE(fs::exists("/usr/bin/pdftoppm")) << "poppler-utils missing (scripts/install-deps.sh installs it)";
    for (const auto& e : fs::directory_iterator(out / "plots")) {
        if (e.path().extension() != ".pdf") continue;
        const fs::path page = dir / ("page_" + e.path().stem().string());
        const Result r = run("pdftoppm -r 60 -png -singlefile '" + e.path().string() + "' '" + page.string() + "'");
        ASSERT_EQ(r.exitCode, 0) << e.path() << "\n" << r.out;
        int pw = 0, ph = 0, pc = 0;
        unsigned char* rendered = stbi_load((page.string() + ".png").c_str(), &pw, &ph, &pc, 3);
        ASSERT_NE(rendered, nullptr) << e.path();
        std::size_t ink = 0;
        for (int i = 0; i < pw * ph; ++i)
            ink += std::min({rendered[3 * i], rendered[3 * i + 1], rendered[3 * i + 2]}) < 200;
        stbi_image_free(rendered);
        EXPECT_GT(ink, std::size_t(pw) * ph / 200) << e.path() << ": a blank page";
    }
    const Result fonts = run("pdffonts '" + (out / "plots" / "cycles-vs-cache.sizeBytes.pdf").string() + "'");
    EXPECT_NE(fonts.out.find("DejaVuSans"), std::string::npos) << fonts.out;
    EXPECT_NE(fonts.out.find(" yes "), std::string::npos) << "the font is embedded\n" << fonts.out;
}
