#include "commands.hpp"

#include <rtlab/core/image.hpp>

#include <cmath>
#include <cstdio>

namespace rtlab::app {

void addCompareCommand(CLI::App& app, CompareOptions& o) {
    CLI::App* cmd = app.add_subcommand("compare", "Compare two EXR images (A against reference B)");
    cmd->add_option("a", o.a, "Test image (.exr)")->required();
    cmd->add_option("b", o.b, "Reference image (.exr)")->required();
}

int runCompare(const CompareOptions& o) {
    const Image a = readExr(o.a);
    const Image b = readExr(o.b);
    const ImageDifference d = compareImages(a, b);
    std::printf("channels: %zu\n", d.channelsCompared);
    std::printf("max_abs_diff: %.9g\n", d.maxAbsDiff);
    std::printf("rmse: %.9g\n", d.rmse);
    if (std::isinf(d.psnr)) std::printf("psnr: inf\n");
    else std::printf("psnr: %.4f\n", d.psnr);
    std::printf("relmse: %.9g\n", d.relMse);
    std::printf("relmse_worst_percent_share: %.6f\n", d.relMseWorstPercentShare);
    if (std::isnan(d.ssim)) std::printf("ssim: n/a (no R, G, B in both)\n");
    else std::printf("ssim: %.6f\n", d.ssim);
    if (d.nonFiniteValues) std::printf("non_finite_values: %zu\n", d.nonFiniteValues);
    std::printf("identical: %s\n", d.identical ? "true" : "false");
    return 0;
}

}  // namespace rtlab::app
