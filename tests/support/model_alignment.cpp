// Model-to-layout alignment by congruent triangles, for tests and evaluations.
#include "tests/support/model_alignment.hpp"

#include <cmath>
#include <optional>

#include "core/rigid_fit.hpp"

namespace edgetrack::test {

namespace {

void assign(const MarkerModel& model, const std::vector<Vec3>& layout, double tolerance_mm,
            const RigidTransform& transform, ModelAlignment& out) {
    const auto& pm = model.markers_model_mm;
    out.T_layout_from_model = transform;
    out.layoutMarkerOf.assign(pm.size(), -1);
    out.matched = 0;
    for (std::size_t i = 0; i < pm.size(); ++i) {
        double best = tolerance_mm;
        for (std::size_t j = 0; j < layout.size(); ++j) {
            const double d = (transform.apply(pm[i]) - layout[j]).norm();
            if (d < best) {
                best = d;
                out.layoutMarkerOf[i] = static_cast<int>(j);
            }
        }
        out.matched += out.layoutMarkerOf[i] >= 0 ? 1u : 0u;
    }
}

} // namespace

ModelAlignment alignModel(const MarkerModel& model, const std::vector<Vec3>& layout,
                          double tolerance_mm) {
    ModelAlignment best;
    best.layoutMarkerOf.assign(model.markers_model_mm.size(), -1);
    const auto& pm = model.markers_model_mm;
    const std::size_t n = pm.size();
    // One well-shaped triangle per model marker: the marker, its farthest co-visible neighbour,
    // and the neighbour of both farthest from their line. Trying n triangles, not every one,
    // keeps this fast enough to run under qemu.
    for (std::size_t i = 0; i < n && best.matched < n; ++i) {
        std::size_t j = n, k = n;
        double far = 0.0, height = 10.0;
        for (std::size_t x = 0; x < n; ++x)
            if (x != i && model.hasEdge(i, x) && (pm[x] - pm[i]).norm() > far) {
                far = (pm[x] - pm[i]).norm();
                j = x;
            }
        if (j == n)
            continue;
        for (std::size_t x = 0; x < n; ++x) {
            if (x == i || x == j || !model.hasEdge(i, x) || !model.hasEdge(j, x))
                continue;
            const double h = (pm[j] - pm[i]).cross(pm[x] - pm[i]).norm() / far;
            if (h > height) {
                height = h;
                k = x;
            }
        }
        if (k == n)
            continue;
        const double dab = (pm[i] - pm[j]).norm();
        const double dak = (pm[i] - pm[k]).norm();
        const double dbk = (pm[j] - pm[k]).norm();
        for (std::size_t a = 0; a < layout.size(); ++a)
            for (std::size_t b = 0; b < layout.size(); ++b) {
                if (a == b || std::abs((layout[a] - layout[b]).norm() - dab) > tolerance_mm)
                    continue;
                for (std::size_t c = 0; c < layout.size(); ++c) {
                    if (c == a || c == b ||
                        std::abs((layout[a] - layout[c]).norm() - dak) > tolerance_mm ||
                        std::abs((layout[b] - layout[c]).norm() - dbk) > tolerance_mm)
                        continue;
                    const Vec3 from[3] = {pm[i], pm[j], pm[k]};
                    const Vec3 to[3] = {layout[a], layout[b], layout[c]};
                    const std::optional<RigidFit> fit = fitRigid(from, to);
                    if (!fit)
                        continue;
                    ModelAlignment candidate;
                    assign(model, layout, tolerance_mm, fit->transform, candidate);
                    if (candidate.matched > best.matched)
                        best = candidate;
                }
            }
    }
    // Refine on every matched pair, twice (the matches may change with the better transform).
    for (int round = 0; round < 2 && best.matched >= 3; ++round) {
        std::vector<Vec3> from, to;
        for (std::size_t i = 0; i < n; ++i)
            if (best.layoutMarkerOf[i] >= 0) {
                from.push_back(pm[i]);
                to.push_back(layout[static_cast<std::size_t>(best.layoutMarkerOf[i])]);
            }
        const std::optional<RigidFit> fit = fitRigid(from, to);
        if (!fit)
            break;
        assign(model, layout, tolerance_mm, fit->transform, best);
        best.rms_mm = fit->rms_mm;
    }
    return best;
}

} // namespace edgetrack::test
