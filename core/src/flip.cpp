// FLIP (Andersson et al. 2020) and HDR-FLIP (Andersson et al. 2021), written
// from the papers; constants checked against NVIDIA's public reference code.
//
// Per image, LDR-FLIP computes:
//  1. colour pipeline: linear RGB -> YyCxCz opponent space, each channel
//     blurred by its contrast sensitivity function (CSF), back to linear RGB
//     clamped to [0, 1], -> CIELAB with the Hunt adjustment;
//  2. feature pipeline: edge (1st Gaussian derivative) and point (2nd
//     derivative) responses of the normalised luminance.
// Per pixel it combines them: HyAB colour distance, compressed to [0, 1]
// (deltaEc), and the feature difference deltaEf, as deltaEc^(1 - deltaEf).
//
// Every 2D kernel here is a product of 1D kernels (a CSF is a sum of such
// products), so each is applied as a row pass and a column pass: the same
// weights as the papers' 2D kernels, far fewer operations. Borders clamp
// (replicate the edge pixel), as the reference code pads. Every output pixel
// is computed from its neighbourhood only, with a fixed summation order, so
// the row-band parallelism cannot change a bit.
#include <rtlab/core/flip.hpp>
#include <rtlab/core/parallel.hpp>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace rtlab {

namespace {

constexpr double kPiDouble = 3.14159265358979323846;

// --- Constants of the FLIP paper (HPG 2020) --------------------------------

// Colour pipeline, spatial filtering: each opponent channel's CSF is a sum of
// Gaussians in the spatial domain,
//   s(x) = a1 sqrt(pi / b1) exp(-pi^2 x^2 / b1) + a2 sqrt(pi / b2) exp(-pi^2 x^2 / b2),
// x in degrees of visual angle; (a1, b1, a2, b2) per channel from the paper's
// CSF fits (achromatic and red-green low-pass, blue-yellow with two terms).
struct CsfParameters {
    double a1, b1, a2, b2;
};
constexpr CsfParameters kCsfAchromatic{1.0, 0.0047, 0.0, 0.0};
constexpr CsfParameters kCsfRedGreen{1.0, 0.0053, 0.0, 0.0};
constexpr CsfParameters kCsfBlueYellow{34.1, 0.04, 13.5, 0.025};
// The CSF kernels share one radius: 3 standard deviations of the widest
// Gaussian, sigma = sqrt(b / (2 pi^2)) degrees, b = max of all b above.
constexpr double kCsfWidestB = 0.04;

// Colour metric: HyAB distance raised to qc, then piecewise-linearly mapped to
// [0, 1] so that pc * cmax -> pt and cmax -> 1 (paper: qc = 0.7, pc = 0.4,
// pt = 0.95; cmax is the HyAB distance of pure green and pure blue, the
// largest of any two colours in the RGB cube, to the power qc).
constexpr double kQc = 0.7;
constexpr double kPc = 0.4;
constexpr double kPt = 0.95;

// Feature pipeline: edge and point detectors are the first and second
// derivatives of a Gaussian with standard deviation 0.5 * w degrees, w = 0.082
// degrees the peak-to-trough width of the human edge detector; radius
// ceil(3 sigma) pixels; positive weights normalised to sum 1, negative to -1.
constexpr double kFeatureWidthDegrees = 0.082;
// deltaEf = (max(|edge difference|, |point difference|) / sqrt(2))^qf, qf = 0.5.
constexpr double kQf = 0.5;

// Upper limit of FlipOptions::pixelsPerDegree: kernels grow linearly with it
// (13500 pixels wide at the limit), and far beyond it their radii overflow.
constexpr double kMaxPixelsPerDegree = 1e5;

// --- Colour spaces ----------------------------------------------------------

// Linear sRGB (Rec. 709 primaries, D65 white; IEC 61966-2-1) -> CIE XYZ, as
// exact fractions (the values the FLIP reference code uses). Row sums give
// the D65 white point (Xn, Yn, Zn) = (0.950428, 1, 1.088900).
constexpr std::array<std::array<double, 3>, 3> kRgbToXyz{{
    {10135552.0 / 24577794.0, 8788810.0 / 24577794.0, 4435075.0 / 24577794.0},
    {2613072.0 / 12288897.0, 8788810.0 / 12288897.0, 887015.0 / 12288897.0},
    {1425312.0 / 73733382.0, 8788810.0 / 73733382.0, 70074185.0 / 73733382.0},
}};

// --- HDR-FLIP constants (Eurographics 2021) ---------------------------------

// Tone mapper: Narkowicz's ACES filmic fit (2016), including the 0.6 input
// scale of his shader, as a rational polynomial
//   t(x) = (k0 x^2 + k1 x + k2) / (k3 x^2 + k4 x + k5), clamped to [0, 1].
constexpr std::array<double, 6> kAces{0.6 * 0.6 * 2.51, 0.6 * 0.03, 0.0, 0.6 * 0.6 * 2.43, 0.6 * 0.59, 0.14};
// The exposure range maps the reference's maximum luminance (start) and
// median luminance (stop) to the tone-mapper input whose output is 0.85.
constexpr double kToneMappedTarget = 0.85;
// Luminance of linear Rec. 709 RGB (ITU-R BT.709), for the exposure range.
constexpr double kLumaR = 0.2126, kLumaG = 0.7152, kLumaB = 0.0722;
// HDR inputs are clamped to [0, 65536] (as the reference implementation does),
// so that +inf and huge outliers cannot stretch the exposure range forever.
constexpr float kHdrMaxValue = 65536.f;

// matplotlib's "magma" colour map (sRGB display values, CC0), which the FLIP
// papers and tool use to show error maps: entry i is error i / 255.
constexpr std::array<std::array<float, 3>, 256> kMagma{{
    {0.001462f, 0.000466f, 0.013866f}, {0.002258f, 0.001295f, 0.018331f}, {0.003279f, 0.002305f, 0.023708f},
    {0.004512f, 0.003490f, 0.029965f}, {0.005950f, 0.004843f, 0.037130f}, {0.007588f, 0.006356f, 0.044973f},
    {0.009426f, 0.008022f, 0.052844f}, {0.011465f, 0.009828f, 0.060750f}, {0.013708f, 0.011771f, 0.068667f},
    {0.016156f, 0.013840f, 0.076603f}, {0.018815f, 0.016026f, 0.084584f}, {0.021692f, 0.018320f, 0.092610f},
    {0.024792f, 0.020715f, 0.100676f}, {0.028123f, 0.023201f, 0.108787f}, {0.031696f, 0.025765f, 0.116965f},
    {0.035520f, 0.028397f, 0.125209f}, {0.039608f, 0.031090f, 0.133515f}, {0.043830f, 0.033830f, 0.141886f},
    {0.048062f, 0.036607f, 0.150327f}, {0.052320f, 0.039407f, 0.158841f}, {0.056615f, 0.042160f, 0.167446f},
    {0.060949f, 0.044794f, 0.176129f}, {0.065330f, 0.047318f, 0.184892f}, {0.069764f, 0.049726f, 0.193735f},
    {0.074257f, 0.052017f, 0.202660f}, {0.078815f, 0.054184f, 0.211667f}, {0.083446f, 0.056225f, 0.220755f},
    {0.088155f, 0.058133f, 0.229922f}, {0.092949f, 0.059904f, 0.239164f}, {0.097833f, 0.061531f, 0.248477f},
    {0.102815f, 0.063010f, 0.257854f}, {0.107899f, 0.064335f, 0.267289f}, {0.113094f, 0.065492f, 0.276784f},
    {0.118405f, 0.066479f, 0.286321f}, {0.123833f, 0.067295f, 0.295879f}, {0.129380f, 0.067935f, 0.305443f},
    {0.135053f, 0.068391f, 0.315000f}, {0.140858f, 0.068654f, 0.324538f}, {0.146785f, 0.068738f, 0.334011f},
    {0.152839f, 0.068637f, 0.343404f}, {0.159018f, 0.068354f, 0.352688f}, {0.165308f, 0.067911f, 0.361816f},
    {0.171713f, 0.067305f, 0.370771f}, {0.178212f, 0.066576f, 0.379497f}, {0.184801f, 0.065732f, 0.387973f},
    {0.191460f, 0.064818f, 0.396152f}, {0.198177f, 0.063862f, 0.404009f}, {0.204935f, 0.062907f, 0.411514f},
    {0.211718f, 0.061992f, 0.418647f}, {0.218512f, 0.061158f, 0.425392f}, {0.225302f, 0.060445f, 0.431742f},
    {0.232077f, 0.059889f, 0.437695f}, {0.238826f, 0.059517f, 0.443256f}, {0.245543f, 0.059352f, 0.448436f},
    {0.252220f, 0.059415f, 0.453248f}, {0.258857f, 0.059706f, 0.457710f}, {0.265447f, 0.060237f, 0.461840f},
    {0.271994f, 0.060994f, 0.465660f}, {0.278493f, 0.061978f, 0.469190f}, {0.284951f, 0.063168f, 0.472451f},
    {0.291366f, 0.064553f, 0.475462f}, {0.297740f, 0.066117f, 0.478243f}, {0.304081f, 0.067835f, 0.480812f},
    {0.310382f, 0.069702f, 0.483186f}, {0.316654f, 0.071690f, 0.485380f}, {0.322899f, 0.073782f, 0.487408f},
    {0.329114f, 0.075972f, 0.489287f}, {0.335308f, 0.078236f, 0.491024f}, {0.341482f, 0.080564f, 0.492631f},
    {0.347636f, 0.082946f, 0.494121f}, {0.353773f, 0.085373f, 0.495501f}, {0.359898f, 0.087831f, 0.496778f},
    {0.366012f, 0.090314f, 0.497960f}, {0.372116f, 0.092816f, 0.499053f}, {0.378211f, 0.095332f, 0.500067f},
    {0.384299f, 0.097855f, 0.501002f}, {0.390384f, 0.100379f, 0.501864f}, {0.396467f, 0.102902f, 0.502658f},
    {0.402548f, 0.105420f, 0.503386f}, {0.408629f, 0.107930f, 0.504052f}, {0.414709f, 0.110431f, 0.504662f},
    {0.420791f, 0.112920f, 0.505215f}, {0.426877f, 0.115395f, 0.505714f}, {0.432967f, 0.117855f, 0.506160f},
    {0.439062f, 0.120298f, 0.506555f}, {0.445163f, 0.122724f, 0.506901f}, {0.451271f, 0.125132f, 0.507198f},
    {0.457386f, 0.127522f, 0.507448f}, {0.463508f, 0.129893f, 0.507652f}, {0.469640f, 0.132245f, 0.507809f},
    {0.475780f, 0.134577f, 0.507921f}, {0.481929f, 0.136891f, 0.507989f}, {0.488088f, 0.139186f, 0.508011f},
    {0.494258f, 0.141462f, 0.507988f}, {0.500438f, 0.143719f, 0.507920f}, {0.506629f, 0.145958f, 0.507806f},
    {0.512831f, 0.148179f, 0.507648f}, {0.519045f, 0.150383f, 0.507443f}, {0.525270f, 0.152569f, 0.507192f},
    {0.531507f, 0.154739f, 0.506895f}, {0.537755f, 0.156894f, 0.506551f}, {0.544015f, 0.159033f, 0.506159f},
    {0.550287f, 0.161158f, 0.505719f}, {0.556571f, 0.163269f, 0.505230f}, {0.562866f, 0.165368f, 0.504692f},
    {0.569172f, 0.167454f, 0.504105f}, {0.575490f, 0.169530f, 0.503466f}, {0.581819f, 0.171596f, 0.502777f},
    {0.588158f, 0.173652f, 0.502035f}, {0.594508f, 0.175701f, 0.501241f}, {0.600868f, 0.177743f, 0.500394f},
    {0.607238f, 0.179779f, 0.499492f}, {0.613617f, 0.181811f, 0.498536f}, {0.620005f, 0.183840f, 0.497524f},
    {0.626401f, 0.185867f, 0.496456f}, {0.632805f, 0.187893f, 0.495332f}, {0.639216f, 0.189921f, 0.494150f},
    {0.645633f, 0.191952f, 0.492910f}, {0.652056f, 0.193986f, 0.491611f}, {0.658483f, 0.196027f, 0.490253f},
    {0.664915f, 0.198075f, 0.488836f}, {0.671349f, 0.200133f, 0.487358f}, {0.677786f, 0.202203f, 0.485819f},
    {0.684224f, 0.204286f, 0.484219f}, {0.690661f, 0.206384f, 0.482558f}, {0.697098f, 0.208501f, 0.480835f},
    {0.703532f, 0.210638f, 0.479049f}, {0.709962f, 0.212797f, 0.477201f}, {0.716387f, 0.214982f, 0.475290f},
    {0.722805f, 0.217194f, 0.473316f}, {0.729216f, 0.219437f, 0.471279f}, {0.735616f, 0.221713f, 0.469180f},
    {0.742004f, 0.224025f, 0.467018f}, {0.748378f, 0.226377f, 0.464794f}, {0.754737f, 0.228772f, 0.462509f},
    {0.761077f, 0.231214f, 0.460162f}, {0.767398f, 0.233705f, 0.457755f}, {0.773695f, 0.236249f, 0.455289f},
    {0.779968f, 0.238851f, 0.452765f}, {0.786212f, 0.241514f, 0.450184f}, {0.792427f, 0.244242f, 0.447543f},
    {0.798608f, 0.247040f, 0.444848f}, {0.804752f, 0.249911f, 0.442102f}, {0.810855f, 0.252861f, 0.439305f},
    {0.816914f, 0.255895f, 0.436461f}, {0.822926f, 0.259016f, 0.433573f}, {0.828886f, 0.262229f, 0.430644f},
    {0.834791f, 0.265540f, 0.427671f}, {0.840636f, 0.268953f, 0.424666f}, {0.846416f, 0.272473f, 0.421631f},
    {0.852126f, 0.276106f, 0.418573f}, {0.857763f, 0.279857f, 0.415496f}, {0.863320f, 0.283729f, 0.412403f},
    {0.868793f, 0.287728f, 0.409303f}, {0.874176f, 0.291859f, 0.406205f}, {0.879464f, 0.296125f, 0.403118f},
    {0.884651f, 0.300530f, 0.400047f}, {0.889731f, 0.305079f, 0.397002f}, {0.894700f, 0.309773f, 0.393995f},
    {0.899552f, 0.314616f, 0.391037f}, {0.904281f, 0.319610f, 0.388137f}, {0.908884f, 0.324755f, 0.385308f},
    {0.913354f, 0.330052f, 0.382563f}, {0.917689f, 0.335500f, 0.379915f}, {0.921884f, 0.341098f, 0.377376f},
    {0.925937f, 0.346844f, 0.374959f}, {0.929845f, 0.352734f, 0.372677f}, {0.933606f, 0.358764f, 0.370541f},
    {0.937221f, 0.364929f, 0.368567f}, {0.940687f, 0.371224f, 0.366762f}, {0.944006f, 0.377643f, 0.365136f},
    {0.947180f, 0.384178f, 0.363701f}, {0.950210f, 0.390820f, 0.362468f}, {0.953099f, 0.397563f, 0.361438f},
    {0.955849f, 0.404400f, 0.360619f}, {0.958464f, 0.411324f, 0.360014f}, {0.960949f, 0.418323f, 0.359630f},
    {0.963310f, 0.425390f, 0.359469f}, {0.965549f, 0.432519f, 0.359529f}, {0.967671f, 0.439703f, 0.359810f},
    {0.969680f, 0.446936f, 0.360311f}, {0.971582f, 0.454210f, 0.361030f}, {0.973381f, 0.461520f, 0.361965f},
    {0.975082f, 0.468861f, 0.363111f}, {0.976690f, 0.476226f, 0.364466f}, {0.978210f, 0.483612f, 0.366025f},
    {0.979645f, 0.491014f, 0.367783f}, {0.981000f, 0.498428f, 0.369734f}, {0.982279f, 0.505851f, 0.371874f},
    {0.983485f, 0.513280f, 0.374198f}, {0.984622f, 0.520713f, 0.376698f}, {0.985693f, 0.528148f, 0.379371f},
    {0.986700f, 0.535582f, 0.382210f}, {0.987646f, 0.543015f, 0.385210f}, {0.988533f, 0.550446f, 0.388365f},
    {0.989363f, 0.557873f, 0.391671f}, {0.990138f, 0.565296f, 0.395122f}, {0.990871f, 0.572706f, 0.398714f},
    {0.991558f, 0.580107f, 0.402441f}, {0.992196f, 0.587502f, 0.406299f}, {0.992785f, 0.594891f, 0.410283f},
    {0.993326f, 0.602275f, 0.414390f}, {0.993834f, 0.609644f, 0.418613f}, {0.994309f, 0.616999f, 0.422950f},
    {0.994738f, 0.624350f, 0.427397f}, {0.995122f, 0.631696f, 0.431951f}, {0.995480f, 0.639027f, 0.436607f},
    {0.995810f, 0.646344f, 0.441361f}, {0.996096f, 0.653659f, 0.446213f}, {0.996341f, 0.660969f, 0.451160f},
    {0.996580f, 0.668256f, 0.456192f}, {0.996775f, 0.675541f, 0.461314f}, {0.996925f, 0.682828f, 0.466526f},
    {0.997077f, 0.690088f, 0.471811f}, {0.997186f, 0.697349f, 0.477182f}, {0.997254f, 0.704611f, 0.482635f},
    {0.997325f, 0.711848f, 0.488154f}, {0.997351f, 0.719089f, 0.493755f}, {0.997351f, 0.726324f, 0.499428f},
    {0.997341f, 0.733545f, 0.505167f}, {0.997285f, 0.740772f, 0.510983f}, {0.997228f, 0.747981f, 0.516859f},
    {0.997138f, 0.755190f, 0.522806f}, {0.997019f, 0.762398f, 0.528821f}, {0.996898f, 0.769591f, 0.534892f},
    {0.996727f, 0.776795f, 0.541039f}, {0.996571f, 0.783977f, 0.547233f}, {0.996369f, 0.791167f, 0.553499f},
    {0.996162f, 0.798348f, 0.559820f}, {0.995932f, 0.805527f, 0.566202f}, {0.995680f, 0.812706f, 0.572645f},
    {0.995424f, 0.819875f, 0.579140f}, {0.995131f, 0.827052f, 0.585701f}, {0.994851f, 0.834213f, 0.592307f},
    {0.994524f, 0.841387f, 0.598983f}, {0.994222f, 0.848540f, 0.605696f}, {0.993866f, 0.855711f, 0.612482f},
    {0.993545f, 0.862859f, 0.619299f}, {0.993170f, 0.870024f, 0.626189f}, {0.992831f, 0.877168f, 0.633109f},
    {0.992440f, 0.884330f, 0.640099f}, {0.992089f, 0.891470f, 0.647116f}, {0.991688f, 0.898627f, 0.654202f},
    {0.991332f, 0.905763f, 0.661309f}, {0.990930f, 0.912915f, 0.668481f}, {0.990570f, 0.920049f, 0.675675f},
    {0.990175f, 0.927196f, 0.682926f}, {0.989815f, 0.934329f, 0.690198f}, {0.989434f, 0.941470f, 0.697519f},
    {0.989077f, 0.948604f, 0.704863f}, {0.988717f, 0.955742f, 0.712242f}, {0.988367f, 0.962878f, 0.719649f},
    {0.988033f, 0.970012f, 0.727077f}, {0.987691f, 0.977154f, 0.734536f}, {0.987387f, 0.984288f, 0.742002f},
    {0.987053f, 0.991438f, 0.749504f},
}};

using Plane = std::vector<float>;

struct Matrix3 {
    std::array<std::array<float, 3>, 3> m{};
    vec3 operator*(const vec3& v) const {
        return {m[0][0] * v.x + m[0][1] * v.y + m[0][2] * v.z, m[1][0] * v.x + m[1][1] * v.y + m[1][2] * v.z,
                m[2][0] * v.x + m[2][1] * v.y + m[2][2] * v.z};
    }
};

// The colour-space constants in float, derived once from kRgbToXyz.
struct ColourSpaces {
    Matrix3 rgbToXyz;
    Matrix3 xyzToRgb;
    vec3 white;         // D65 (Xn, Yn, Zn)
    vec3 inverseWhite;  // 1 / white

    ColourSpaces() {
        // Inverse of the 3x3 matrix by cofactors, in double.
        const auto& a = kRgbToXyz;
        const double det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) -
                           a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0]) +
                           a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
        std::array<std::array<double, 3>, 3> inverse{};
        for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 3; ++c) {
                // inverse[r][c] = cofactor(c, r) / det
                const int r0 = (c + 1) % 3, r1 = (c + 2) % 3, c0 = (r + 1) % 3, c1 = (r + 2) % 3;
                inverse[r][c] = (a[r0][c0] * a[r1][c1] - a[r0][c1] * a[r1][c0]) / det;
            }
        for (int r = 0; r < 3; ++r) {
            for (int c = 0; c < 3; ++c) {
                rgbToXyz.m[r][c] = static_cast<float>(a[r][c]);
                xyzToRgb.m[r][c] = static_cast<float>(inverse[r][c]);
            }
            const double rowSum = a[r][0] + a[r][1] + a[r][2];
            white[r] = static_cast<float>(rowSum);
            inverseWhite[r] = static_cast<float>(1.0 / rowSum);
        }
    }
};

const ColourSpaces& colourSpaces() {
    static const ColourSpaces spaces;
    return spaces;
}

// YyCxCz: the opponent space of the colour pipeline, CIELAB without its cube
// root (linear in XYZ, so blurring in it is blurring light):
// Yy = 116 y - 16, Cx = 500 (x - y), Cz = 200 (y - z), (x, y, z) = XYZ / white.
vec3 linearRgbToYcxcz(const vec3& rgb) {
    const ColourSpaces& cs = colourSpaces();
    const vec3 n = (cs.rgbToXyz * rgb) * cs.inverseWhite;
    return {116.f * n.y - 16.f, 500.f * (n.x - n.y), 200.f * (n.y - n.z)};
}

vec3 ycxczToLinearRgb(const vec3& ycxcz) {
    const ColourSpaces& cs = colourSpaces();
    const float y = (ycxcz.x + 16.f) / 116.f;
    const vec3 n{y + ycxcz.y / 500.f, y, y - ycxcz.z / 200.f};
    return cs.xyzToRgb * (n * cs.white);
}

// Cube root of t > 0: a first guess from the float's bits (exponent / 3,
// relative error < 3.5%), then two Halley steps y <- y (y^3 + 2t) / (2y^3 + t)
// in double, each cubing the relative error (3.5% -> 4e-5 -> 1e-13). For every
// float in [0.008, 1.2] (all that CIELAB sees here) this is the correctly
// rounded cube root, at a fraction of glibc's cbrtf cost.
float cubeRoot(float t) {
    const std::uint32_t guessBits = std::bit_cast<std::uint32_t>(t) / 3u + 0x2a514067u;
    double y = std::bit_cast<float>(guessBits);
    const double target = t;
    for (int step = 0; step < 2; ++step) {
        const double cube = y * y * y;
        y *= (cube + 2.0 * target) / (2.0 * cube + target);
    }
    return static_cast<float>(y);
}

// CIELAB's f(t): cube root above (6/29)^3, a line below (CIE 15).
float labF(float t) {
    constexpr float delta = 6.f / 29.f;
    constexpr float deltaCube = delta * delta * delta;
    return t > deltaCube ? cubeRoot(t) : t / (3.f * delta * delta) + 4.f / 29.f;
}

// CIELAB (D65) with the Hunt adjustment of the FLIP paper: a* and b* scaled
// by 0.01 L*, as colourfulness drops with lightness.
vec3 linearRgbToHuntLab(const vec3& rgb) {
    const ColourSpaces& cs = colourSpaces();
    const vec3 n = (cs.rgbToXyz * rgb) * cs.inverseWhite;
    const float fx = labF(n.x), fy = labF(n.y), fz = labF(n.z);
    const float lightness = 116.f * fy - 16.f;
    return {lightness, 0.01f * lightness * 500.f * (fx - fy), 0.01f * lightness * 200.f * (fy - fz)};
}

// HyAB (Abasi et al. 2020): city-block in L*, Euclidean in (a*, b*).
float hyab(const vec3& a, const vec3& b) {
    const vec3 d = a - b;
    return std::abs(d.x) + std::sqrt(d.y * d.y + d.z * d.z);
}

// cmax = HyAB(green, blue)^qc in Hunt-adjusted CIELAB.
double maxColourDistance() {
    static const double cmax =
        std::pow(hyab(linearRgbToHuntLab(vec3(0.f, 1.f, 0.f)), linearRgbToHuntLab(vec3(0.f, 0.f, 1.f))), kQc);
    return cmax;
}

// --- Separable filtering ----------------------------------------------------

// weights[k] applies to offset k - radius.
struct Kernel1d {
    int radius = 0;
    std::vector<float> weights;
};

// The CSF of one channel as one or two separable Gaussians:
// (firstShare * G1 + (1 - firstShare) * G2), each G normalised to sum 1.
struct CsfFilter {
    Kernel1d first;
    Kernel1d second;  // weights empty when the CSF has one term
    float firstShare = 1.f;
};

struct FlipFilters {
    std::array<CsfFilter, 3> csf;  // Yy, Cx, Cz
    Kernel1d featureGaussian;      // sums to 1
    Kernel1d edge;                 // 1st derivative, +1 / -1 normalised
    Kernel1d point;                // 2nd derivative, +1 / -1 normalised
};

// Unnormalised exp(-pi^2 (k / ppd)^2 / b) for pixel offsets k = -radius..radius.
std::vector<double> csfGaussian(double b, int radius, double pixelsPerDegree) {
    std::vector<double> g(static_cast<std::size_t>(2 * radius + 1));
    for (int k = -radius; k <= radius; ++k) {
        const double x = k / pixelsPerDegree;
        g[static_cast<std::size_t>(k + radius)] = std::exp(-kPiDouble * kPiDouble * x * x / b);
    }
    return g;
}

Kernel1d toKernel(const std::vector<double>& values, double scale, int radius) {
    Kernel1d kernel{radius, {}};
    kernel.weights.reserve(values.size());
    for (double v : values) kernel.weights.push_back(static_cast<float>(v * scale));
    return kernel;
}

double sum(const std::vector<double>& values) {
    double total = 0.0;
    for (double v : values) total += v;
    return total;
}

CsfFilter makeCsfFilter(const CsfParameters& p, int radius, double pixelsPerDegree) {
    // The 2D kernel a sqrt(pi/b) G(x) G(y) sums to a sqrt(pi/b) S^2 (S = sum of
    // G), so normalising the whole 2D CSF gives each term the share
    // a sqrt(pi/b) S^2 / total and each 1D factor the weights G / S.
    CsfFilter filter;
    const std::vector<double> g1 = csfGaussian(p.b1, radius, pixelsPerDegree);
    const double s1 = sum(g1);  // >= 1: the centre weight is exp(0)
    filter.first = toKernel(g1, 1.0 / s1, radius);
    if (p.a2 == 0.0) return filter;
    const std::vector<double> g2 = csfGaussian(p.b2, radius, pixelsPerDegree);
    const double s2 = sum(g2);
    filter.second = toKernel(g2, 1.0 / s2, radius);
    const double mass1 = p.a1 * std::sqrt(kPiDouble / p.b1) * s1 * s1;
    const double mass2 = p.a2 * std::sqrt(kPiDouble / p.b2) * s2 * s2;
    filter.firstShare = static_cast<float>(mass1 / (mass1 + mass2));
    return filter;
}

// Positive weights scaled to sum 1, negative ones to sum -1 (zero stays 0).
Kernel1d normalisedSignedKernel(const std::vector<double>& values, int radius) {
    double positive = 0.0, negative = 0.0;
    for (double v : values) (v > 0.0 ? positive : negative) += v;
    Kernel1d kernel{radius, {}};
    for (double v : values) {
        const double divisor = v > 0.0 ? positive : -negative;
        kernel.weights.push_back(divisor > 0.0 ? static_cast<float>(v / divisor) : 0.f);
    }
    return kernel;
}

FlipFilters makeFilters(double pixelsPerDegree) {
    FlipFilters filters;
    // CSFs: common radius from the widest Gaussian.
    const int csfRadius =
        static_cast<int>(std::ceil(3.0 * std::sqrt(kCsfWidestB / (2.0 * kPiDouble * kPiDouble)) * pixelsPerDegree));
    filters.csf[0] = makeCsfFilter(kCsfAchromatic, csfRadius, pixelsPerDegree);
    filters.csf[1] = makeCsfFilter(kCsfRedGreen, csfRadius, pixelsPerDegree);
    filters.csf[2] = makeCsfFilter(kCsfBlueYellow, csfRadius, pixelsPerDegree);

    // Features: the 2D detectors are D(x) G(y) (and transposed). Normalising
    // the 2D kernel's positive and negative parts equals normalising D's
    // parts and G to sum 1, since each part is a product with all of G.
    const double sigma = 0.5 * kFeatureWidthDegrees * pixelsPerDegree;
    const int radius = std::max(1, static_cast<int>(std::ceil(3.0 * sigma)));
    std::vector<double> gaussian, edge, point;
    for (int k = -radius; k <= radius; ++k) {
        const double x = k;
        const double g = std::exp(-x * x / (2.0 * sigma * sigma));
        gaussian.push_back(g);
        edge.push_back(-x * g);
        point.push_back((x * x / (sigma * sigma) - 1.0) * g);
    }
    filters.featureGaussian = toKernel(gaussian, 1.0 / sum(gaussian), radius);
    filters.edge = normalisedSignedKernel(edge, radius);
    filters.point = normalisedSignedKernel(point, radius);
    return filters;
}

// Runs body(y0, y1) over bands of rows, in parallel. Rows are independent, so
// the band layout and thread count do not affect any value.
template <class Body>
void forEachRowBand(int height, Body&& body) {
    constexpr int kRowsPerBand = 8;
    const int bands = (height + kRowsPerBand - 1) / kRowsPerBand;
    parallelForEach(static_cast<std::size_t>(bands), [&](std::size_t band) {
        const int y0 = static_cast<int>(band) * kRowsPerBand;
        body(y0, std::min(height, y0 + kRowsPerBand));
    });
}

// How a pass weighs its taps: plain, or relative to the centre pixel
// (sum w_k (v_k - v_centre)). The latter equals the plain sum for kernels that
// sum to zero (the derivative kernels), but gives exactly 0 on flat regions
// instead of rounding noise that deltaEf's square root would amplify.
enum class Taps { Plain, RelativeToCentre };

// dst(x, y) = sum_k w_k src(clamp(x + k - r), y).
void filterRows(const Plane& src, Plane& dst, int width, int height, const Kernel1d& kernel, Taps taps) {
    const int r = kernel.radius;
    forEachRowBand(height, [&](int y0, int y1) {
        std::vector<float> padded(static_cast<std::size_t>(width + 2 * r));
        std::vector<float> sumRow(static_cast<std::size_t>(width));
        for (int y = y0; y < y1; ++y) {
            const float* row = src.data() + static_cast<std::size_t>(y) * width;
            for (int i = 0; i < width + 2 * r; ++i) padded[i] = row[std::clamp(i - r, 0, width - 1)];
            std::fill(sumRow.begin(), sumRow.end(), 0.f);
            const float* centre = padded.data() + r;
            for (int k = 0; k <= 2 * r; ++k) {
                const float w = kernel.weights[k];
                const float* tap = padded.data() + k;
                if (taps == Taps::Plain)
                    for (int x = 0; x < width; ++x) sumRow[x] += w * tap[x];
                else
                    for (int x = 0; x < width; ++x) sumRow[x] += w * (tap[x] - centre[x]);
            }
            std::copy(sumRow.begin(), sumRow.end(), dst.begin() + static_cast<std::ptrdiff_t>(y) * width);
        }
    });
}

// dst(x, y) = sum_k w_k src(x, clamp(y + k - r)).
void filterColumns(const Plane& src, Plane& dst, int width, int height, const Kernel1d& kernel, Taps taps) {
    const int r = kernel.radius;
    forEachRowBand(height, [&](int y0, int y1) {
        std::vector<float> sumRow(static_cast<std::size_t>(width));
        for (int y = y0; y < y1; ++y) {
            std::fill(sumRow.begin(), sumRow.end(), 0.f);
            const float* centre = src.data() + static_cast<std::size_t>(y) * width;
            for (int k = 0; k <= 2 * r; ++k) {
                const float w = kernel.weights[k];
                const float* tap = src.data() + static_cast<std::size_t>(std::clamp(y + k - r, 0, height - 1)) * width;
                if (taps == Taps::Plain)
                    for (int x = 0; x < width; ++x) sumRow[x] += w * tap[x];
                else
                    for (int x = 0; x < width; ++x) sumRow[x] += w * (tap[x] - centre[x]);
            }
            std::copy(sumRow.begin(), sumRow.end(), dst.begin() + static_cast<std::ptrdiff_t>(y) * width);
        }
    });
}

// Runs body(i) for every pixel index, in parallel row bands.
template <class Body>
void forEachPixel(int width, int height, Body&& body) {
    forEachRowBand(height, [&](int y0, int y1) {
        const std::size_t end = static_cast<std::size_t>(y1) * width;
        for (std::size_t i = static_cast<std::size_t>(y0) * width; i < end; ++i) body(i);
    });
}

// --- LDR-FLIP ----------------------------------------------------------------

// What LDR-FLIP compares of one image.
struct PerceivedImage {
    std::vector<vec3> huntLab;  // CSF-filtered colour, Hunt-adjusted CIELAB
    Plane edgeStrength;         // |(edge_x, edge_y)|
    Plane pointStrength;        // |(point_x, point_y)|
};

// LDR-FLIP with every buffer allocated once, so that HDR-FLIP's exposures
// reuse them (fresh multi-megabyte buffers per pass cost more than the math).
class LdrFlipEvaluator {
public:
    LdrFlipEvaluator(int width, int height, const FlipOptions& options)
        : width_(width), height_(height), filters_(makeFilters(options.pixelsPerDegree)) {
        const std::size_t count = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
        for (Plane* plane :
             {&opponent_[0], &opponent_[1], &opponent_[2], &luminance_, &filtered_[0], &filtered_[1], &filtered_[2],
              &rows_, &secondTerm_, &gaussianRows_, &edgeRows_, &pointRows_, &edgeX_, &edgeY_, &pointX_, &pointY_})
            plane->resize(count);
        for (PerceivedImage* image : {&test_, &reference_}) {
            image->huntLab.resize(count);
            image->edgeStrength.resize(count);
            image->pointStrength.resize(count);
        }
    }

    // Error map of two linear RGB images with values in [0, 1].
    void evaluate(const std::vector<vec3>& testLinear, const std::vector<vec3>& referenceLinear,
                  std::vector<float>& errors) {
        perceive(testLinear, test_);
        perceive(referenceLinear, reference_);
        errors.resize(testLinear.size());
        const auto cmax = static_cast<float>(maxColourDistance());
        const auto inverseSqrt2 = static_cast<float>(1.0 / std::sqrt(2.0));
        forEachPixel(width_, height_, [&](std::size_t i) {
            const float colourError = redistributeColourError(hyab(test_.huntLab[i], reference_.huntLab[i]), cmax);
            const float edgeDifference = std::abs(test_.edgeStrength[i] - reference_.edgeStrength[i]);
            const float pointDifference = std::abs(test_.pointStrength[i] - reference_.pointStrength[i]);
            const float featureError =
                featurePower(std::min(1.f, inverseSqrt2 * std::max(edgeDifference, pointDifference)));
            // Final error: feature differences push the colour error towards 1.
            errors[i] = std::pow(colourError, 1.f - featureError);
        });
    }

private:
    // deltaEc: HyAB^qc mapped to [0, 1], pc * cmax -> pt, cmax -> 1.
    static float redistributeColourError(float hyabDistance, float cmax) {
        const float powered = std::pow(hyabDistance, static_cast<float>(kQc));
        const auto knee = static_cast<float>(kPc) * cmax;
        const auto pt = static_cast<float>(kPt);
        const float mapped =
            powered < knee ? (pt / knee) * powered : pt + ((powered - knee) / (cmax - knee)) * (1.f - pt);
        return std::clamp(mapped, 0.f, 1.f);
    }

    // x^qf; qf = 0.5 is a square root.
    static float featurePower(float x) {
        if constexpr (kQf == 0.5) return std::sqrt(x);
        return std::pow(x, static_cast<float>(kQf));
    }

    // One channel blurred by its CSF (one or two separable Gaussians).
    void applyCsf(const Plane& channel, const CsfFilter& csf, Plane& out) {
        filterRows(channel, rows_, width_, height_, csf.first, Taps::Plain);
        filterColumns(rows_, out, width_, height_, csf.first, Taps::Plain);
        if (csf.second.weights.empty()) return;
        filterRows(channel, rows_, width_, height_, csf.second, Taps::Plain);
        filterColumns(rows_, secondTerm_, width_, height_, csf.second, Taps::Plain);
        const float share = csf.firstShare;
        forEachPixel(width_, height_, [&](std::size_t i) { out[i] = share * out[i] + (1.f - share) * secondTerm_[i]; });
    }

    void perceive(const std::vector<vec3>& linearRgb, PerceivedImage& perceived) {
        // Opponent channels and the normalised luminance y = (Yy + 16) / 116.
        forEachPixel(width_, height_, [&](std::size_t i) {
            const vec3 ycxcz = linearRgbToYcxcz(linearRgb[i]);
            for (int c = 0; c < 3; ++c) opponent_[c][i] = ycxcz[c];
            luminance_[i] = (ycxcz.x + 16.f) / 116.f;
        });

        // Colour pipeline: CSF filtering, back to the RGB cube, Hunt-adjusted Lab.
        for (int c = 0; c < 3; ++c) applyCsf(opponent_[c], filters_.csf[c], filtered_[c]);
        forEachPixel(width_, height_, [&](std::size_t i) {
            const vec3 rgb = ycxczToLinearRgb(vec3(filtered_[0][i], filtered_[1][i], filtered_[2][i]));
            perceived.huntLab[i] = linearRgbToHuntLab(glm::clamp(rgb, vec3(0.f), vec3(1.f)));
        });

        // Feature pipeline: x responses are D(x) G(y), y responses G(x) D(y).
        filterRows(luminance_, gaussianRows_, width_, height_, filters_.featureGaussian, Taps::Plain);
        filterRows(luminance_, edgeRows_, width_, height_, filters_.edge, Taps::RelativeToCentre);
        filterRows(luminance_, pointRows_, width_, height_, filters_.point, Taps::RelativeToCentre);
        filterColumns(edgeRows_, edgeX_, width_, height_, filters_.featureGaussian, Taps::Plain);
        filterColumns(gaussianRows_, edgeY_, width_, height_, filters_.edge, Taps::RelativeToCentre);
        filterColumns(pointRows_, pointX_, width_, height_, filters_.featureGaussian, Taps::Plain);
        filterColumns(gaussianRows_, pointY_, width_, height_, filters_.point, Taps::RelativeToCentre);
        forEachPixel(width_, height_, [&](std::size_t i) {
            perceived.edgeStrength[i] = std::hypot(edgeX_[i], edgeY_[i]);
            perceived.pointStrength[i] = std::hypot(pointX_[i], pointY_[i]);
        });
    }

    int width_;
    int height_;
    FlipFilters filters_;
    std::array<Plane, 3> opponent_;
    Plane luminance_;
    std::array<Plane, 3> filtered_;
    Plane rows_, secondTerm_;
    Plane gaussianRows_, edgeRows_, pointRows_, edgeX_, edgeY_, pointX_, pointY_;
    PerceivedImage test_, reference_;
};

// --- Shared helpers -----------------------------------------------------------

void validate(const char* function, const std::vector<vec3>& test, const std::vector<vec3>& reference, int width,
              int height, const FlipOptions& options) {
    const std::string name(function);
    if (width <= 0 || height <= 0)
        throw std::invalid_argument(name + ": image size must be positive, got " + std::to_string(width) + "x" +
                                    std::to_string(height));
    const std::size_t expected = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
    if (test.size() != expected || reference.size() != expected)
        throw std::invalid_argument(name + ": a " + std::to_string(width) + "x" + std::to_string(height) +
                                    " image needs " + std::to_string(expected) + " pixels, got test " +
                                    std::to_string(test.size()) + " and reference " + std::to_string(reference.size()));
    if (!(options.pixelsPerDegree > 0.0 && options.pixelsPerDegree <= kMaxPixelsPerDegree))
        throw std::invalid_argument(name + ": pixelsPerDegree must be in (0, 100000], got " +
                                    std::to_string(options.pixelsPerDegree));
}

float sanitised(float value, float maxValue) { return std::isnan(value) ? 0.f : std::clamp(value, 0.f, maxValue); }

// Median of `values` (mean of the two middle ones for an even count); reorders.
double median(std::vector<float>& values) {
    if (values.empty()) return 0.0;
    const std::size_t mid = values.size() / 2;
    std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(mid), values.end());
    const double upper = values[mid];
    if (values.size() % 2 == 1) return upper;
    const double lower = *std::max_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(mid));
    return 0.5 * (lower + upper);
}

FlipResult makeResult(std::vector<float> errors, int width, int height) {
    FlipResult result;
    result.width = width;
    result.height = height;
    double total = 0.0;
    float largest = 0.f;
    for (float e : errors) {
        total += e;
        largest = std::max(largest, e);
    }
    result.mean = total / static_cast<double>(errors.size());
    result.maxError = largest;
    std::vector<float> sorted = errors;
    result.median = median(sorted);
    result.errorMap = std::move(errors);
    return result;
}

// --- HDR-FLIP helpers ----------------------------------------------------------

// The tone-mapper input x >= 0 with t(x) = target: the positive root of
// (k0 - t k3) x^2 + (k1 - t k4) x + (k2 - t k5) = 0.
double toneMapperInputFor(double target) {
    const double a = kAces[0] - target * kAces[3];
    const double b = kAces[1] - target * kAces[4];
    const double c = kAces[2] - target * kAces[5];
    if (a == 0.0) return -c / b;
    return (-b + std::sqrt(b * b - 4.0 * a * c)) / (2.0 * a);
}

float acesToneMap(double x) {
    const double numerator = (kAces[0] * x + kAces[1]) * x + kAces[2];
    const double denominator = (kAces[3] * x + kAces[4]) * x + kAces[5];
    return static_cast<float>(std::clamp(numerator / denominator, 0.0, 1.0));
}

struct ExposureRange {
    double start = 0.0;
    double stop = 0.0;
};

// HDR-FLIP's automatic range: start = log2(x85 / Ymax), stop = log2(x85 / Ymedian).
ExposureRange exposureRange(const std::vector<vec3>& reference) {
    std::vector<float> luminances;
    luminances.reserve(reference.size());
    float maxLuminance = 0.f;
    for (const vec3& c : reference) {
        const auto y = static_cast<float>(kLumaR * c.x + kLumaG * c.y + kLumaB * c.z);
        luminances.push_back(y);
        maxLuminance = std::max(maxLuminance, y);
    }
    if (!(maxLuminance > 0.f)) return {};  // black reference: no range to derive; exposure 0
    double medianLuminance = median(luminances);
    if (!(medianLuminance > 0.0)) {
        // Mostly black: log2(x / 0) is infinite, so use the positive pixels' median.
        std::vector<float> positive;
        for (float y : luminances)
            if (y > 0.f) positive.push_back(y);
        medianLuminance = median(positive);
    }
    const double x85 = toneMapperInputFor(kToneMappedTarget);
    return {std::log2(x85 / maxLuminance), std::log2(x85 / medianLuminance)};
}

// ACES of 2^exposure * linear, in [0, 1].
void toneMap(const std::vector<vec3>& linear, double exposureScale, std::vector<vec3>& ldr) {
    for (std::size_t i = 0; i < linear.size(); ++i)
        for (int c = 0; c < 3; ++c) ldr[i][c] = acesToneMap(exposureScale * linear[i][c]);
}

}  // namespace

FlipResult ldrFlip(const std::vector<vec3>& testSrgb, const std::vector<vec3>& referenceSrgb, int width, int height,
                   const FlipOptions& options) {
    validate("ldrFlip", testSrgb, referenceSrgb, width, height, options);
    // Sanitise, then decode sRGB to linear.
    const auto decode = [](const std::vector<vec3>& srgb) {
        std::vector<vec3> linear(srgb.size());
        for (std::size_t i = 0; i < srgb.size(); ++i)
            for (int c = 0; c < 3; ++c) linear[i][c] = srgbToLinear(sanitised(srgb[i][c], 1.f));
        return linear;
    };
    LdrFlipEvaluator evaluator(width, height, options);
    std::vector<float> errors;
    evaluator.evaluate(decode(testSrgb), decode(referenceSrgb), errors);
    return makeResult(std::move(errors), width, height);
}

FlipResult hdrFlip(const std::vector<vec3>& testLinear, const std::vector<vec3>& referenceLinear, int width, int height,
                   const FlipOptions& options) {
    validate("hdrFlip", testLinear, referenceLinear, width, height, options);
    const auto sanitise = [](const std::vector<vec3>& linear) {
        std::vector<vec3> clean(linear.size());
        for (std::size_t i = 0; i < linear.size(); ++i)
            for (int c = 0; c < 3; ++c) clean[i][c] = sanitised(linear[i][c], kHdrMaxValue);
        return clean;
    };
    const std::vector<vec3> test = sanitise(testLinear);
    const std::vector<vec3> reference = sanitise(referenceLinear);

    // At least two exposures, at most one stop apart, start and stop included.
    const ExposureRange range = exposureRange(reference);
    const int exposureCount = std::max(2, static_cast<int>(std::ceil(range.stop - range.start)));
    const double step = (range.stop - range.start) / (exposureCount - 1);

    // Per-pixel maximum of the LDR-FLIP maps of the tone-mapped pairs.
    LdrFlipEvaluator evaluator(width, height, options);
    std::vector<vec3> testLdr(test.size()), referenceLdr(test.size());
    std::vector<float> errors(test.size(), 0.f), exposureErrors;
    for (int i = 0; i < exposureCount; ++i) {
        const double scale = std::exp2(range.start + i * step);
        toneMap(test, scale, testLdr);
        toneMap(reference, scale, referenceLdr);
        evaluator.evaluate(testLdr, referenceLdr, exposureErrors);
        for (std::size_t p = 0; p < errors.size(); ++p) errors[p] = std::max(errors[p], exposureErrors[p]);
    }

    FlipResult result = makeResult(std::move(errors), width, height);
    result.startExposure = range.start;
    result.stopExposure = range.stop;
    result.exposureCount = exposureCount;
    return result;
}

Image flipErrorImage(const FlipResult& result) {
    const std::size_t count = static_cast<std::size_t>(std::max(result.width, 0)) * std::max(result.height, 0);
    if (result.width < 0 || result.height < 0 || result.errorMap.size() != count)
        throw std::invalid_argument("flipErrorImage: error map has " + std::to_string(result.errorMap.size()) +
                                    " values for a " + std::to_string(result.width) + "x" +
                                    std::to_string(result.height) + " image");
    std::vector<vec3> colours(count);
    for (std::size_t i = 0; i < count; ++i) {
        const float error = std::isnan(result.errorMap[i]) ? 0.f : std::clamp(result.errorMap[i], 0.f, 1.f);
        const auto& display = kMagma[static_cast<std::size_t>(error * 255.f + 0.5f)];
        // sRGB decode, so that writePng's encoding gives back magma's colours.
        colours[i] = vec3(srgbToLinear(display[0]), srgbToLinear(display[1]), srgbToLinear(display[2]));
    }
    Image image(result.width, result.height);
    image.addRgbLayer("", colours);
    return image;
}

}  // namespace rtlab
