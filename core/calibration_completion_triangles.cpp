// Completion, triangle step: a body posed from three of its markers where the tracker needs four.
#include <algorithm>
#include <cmath>
#include <numbers>
#include <optional>

#include "core/calibration_completion.hpp"
#include "core/completion_geometry.hpp"
#include "core/rigid_fit.hpp"

namespace edgetrack {

using namespace completion_detail;

// ---------------------------------------------------------------------------------------------
// Poses from three markers

struct CalibrationCompletion::TriangleJob {
    Body* body = nullptr;
    /// Its triangles that no other triangle of any body resembles, by longest side.
    std::vector<SortedTriangle> own;
    /// The longest side of those, plus the tolerance (mm).
    double longest = 0.0;
    Extent ball;
    /// Per marker, the directions it was seen from in the frames posed so far (body frame).
    std::vector<std::vector<Vec3>> seenFrom;
    /// Per frame, whether three points posed it, and the pose.
    std::vector<std::uint8_t> seeded;
    std::vector<RigidTransform> seed;
};

void CalibrationCompletion::poseFromTriangles(const SessionBuffer& session) {
    const std::size_t frames = session.frames();
    if (frames < config_.minTriangleRun)
        return;
    const double tol = config_.triangleTolerance_mm;
    const double apart = config_.triangleUniqueness * tol;

    // The triangles of every alive body; a body's that no other of its own resembles are the ones
    // three points can stand for, where the few other bodies with a triangle like it are found
    // elsewhere (a box of 32 markers has a triangle like nearly any of a small body's, and is in
    // view most of the session). Resembles by a wider margin than a match needs: where a layout's
    // triangles come close to each other (markers evenly spaced on a ring), the triangles of its
    // markers not yet learnt come as close, and three of those would pose it wrongly.
    std::vector<SortedTriangle> all;
    for (std::size_t b = 0; b < bodies_.size(); ++b)
        if (bodies_[b].alive)
            appendTriangles(bodies_[b].markers_mm, b, all);
    markAlike(all, apart);
    std::sort(all.begin(), all.end(), shorterLongestSide);
    std::vector<TriangleJob> ofBody(bodies_.size());
    // Like a triangle of a body not known to be another object (seen moving apart from this one):
    // never this body's alone. A piece of its own object with a like triangle tells that the
    // object is like itself (a box's faces), and three points of its other faces would pose it.
    const auto likeAPiece = [&](const SortedTriangle& t) {
        return std::any_of(
            t.alikeBodies.begin(), t.alikeBodies.begin() + t.alikeCount,
            [&](std::uint32_t o) { return !bodies_[t.body].isApartFrom(bodies_[o].id); });
    };
    for (const SortedTriangle& t : all)
        if (t.unique && wellShaped(t, tol) && !likeAPiece(t))
            ofBody[t.body].own.push_back(t);
    std::vector<TriangleJob> jobs;
    for (std::size_t index = 0; index < bodies_.size(); ++index)
        if (!ofBody[index].own.empty()) {
            ofBody[index].body = &bodies_[index];
            jobs.push_back(std::move(ofBody[index]));
        }
    poseFromTriangles(session, jobs);
}

void CalibrationCompletion::poseFromTriangles(const SessionBuffer& session,
                                              std::vector<TriangleJob>& jobs) {
    const std::size_t frames = session.frames();
    const double tol = config_.triangleTolerance_mm;
    const double radius = kRefineRadiusFactor * config_.siteRadius_mm;
    constexpr double kDegree = std::numbers::pi / 180.0;
    const double thinning = std::cos(0.25 * config_.triangleViewAngle_deg * kDegree);
    for (TriangleJob& job : jobs) {
        const Body& body = *job.body;
        job.longest = job.own.back().sides_mm[2] + tol;
        job.ball = extentOf(body.markers_mm);
        // The directions each marker was seen from in the frames posed so far (body frame,
        // thinned). Three points of something else that match a triangle by chance put the body
        // in a random attitude, from which its markers were hardly ever seen; three of its own
        // markers are seen from about where they were seen before.
        job.seenFrom.assign(body.markers_mm.size(), {});
        for (std::size_t f = 0; f < frames; ++f) {
            if (!body.posed[f])
                continue;
            const RigidTransform& T_rig_from_body = body.T_rig_from_body[f];
            const Vec3 viewpoint = T_rig_from_body.inverse().apply(config_.viewpoint_rig_mm);
            for (std::size_t m = 0; m < body.markers_mm.size(); ++m) {
                if (nearestPoint(session.points(f), T_rig_from_body.apply(body.markers_mm[m]),
                                 radius) == nullptr)
                    continue;
                keepViewDirection(job.seenFrom[m], (viewpoint - body.markers_mm[m]).normalized(),
                                  thinning);
            }
        }
        job.seeded.assign(frames, 0);
        job.seed.resize(frames);
    }

    // Every job's own triangles in one list by longest side (each job's in its own order), so
    // that a frame's triangle is looked up once for all of them.
    std::vector<SortedTriangle> ofJobs;
    for (std::size_t j = 0; j < jobs.size(); ++j)
        for (SortedTriangle t : jobs[j].own) {
            t.body = j;
            ofJobs.push_back(t);
        }
    const TrianglesByLongestSide owned(ofJobs, tol);

    // Points another body's pose explains are looked at too: where two pieces of one object
    // share markers, the tracker gives the shared points to one of them only, and the other piece
    // would never be seen posed with it. So a frame's triangles of points are the same for every
    // body, and are made once.
    std::vector<SortedTriangle> seenTriangles;
    std::vector<double> distances_mm;
    std::vector<std::size_t> bins;
    for (std::size_t f = 0; f < frames; ++f) {
        const std::span<const Vec3> free = session.points(f);
        if (free.size() < 3 || free.size() > config_.maxTrianglePoints)
            continue;
        double longest = 0.0;
        for (const TriangleJob& job : jobs)
            if (!job.body->posed[f])
                longest = std::max(longest, job.longest);
        if (!(longest > 0.0))
            continue;
        // Each distance and its bin once: most triples have a side too long to be any body's,
        // and most of the rest are like none of the bodies' triangles, which the bins of their
        // sides tell without making the triangle.
        const auto n = static_cast<std::uint32_t>(free.size());
        distances_mm.resize(static_cast<std::size_t>(n) * n);
        bins.resize(static_cast<std::size_t>(n) * n);
        for (std::uint32_t i = 0; i < n; ++i)
            for (std::uint32_t j = i + 1; j < n; ++j) {
                distances_mm[i * n + j] = (free[i] - free[j]).norm();
                bins[i * n + j] = owned.binOf(distances_mm[i * n + j]);
            }
        seenTriangles.clear();
        for (std::uint32_t i = 0; i < n; ++i)
            for (std::uint32_t j = i + 1; j < n; ++j) {
                const double ij = distances_mm[i * n + j];
                if (ij > longest)
                    continue;
                const std::size_t binIJ = bins[i * n + j];
                for (std::uint32_t k = j + 1; k < n; ++k) {
                    const double ik = distances_mm[i * n + k], jk = distances_mm[j * n + k];
                    if (ik > longest || jk > longest)
                        continue;
                    const std::size_t binIK = bins[i * n + k], binJK = bins[j * n + k];
                    const std::size_t longestBin = std::max({binIJ, binIK, binJK});
                    const std::size_t middleBin =
                        std::max(std::min(binIJ, binIK), std::min(std::max(binIJ, binIK), binJK));
                    if (owned.mayHoldNear(longestBin, middleBin))
                        seenTriangles.push_back(sortedTriangle(jk, ik, ij, i, j, k));
                }
            }
        poseFromTriangles(free, seenTriangles, owned, jobs, f);
    }

    for (TriangleJob& job : jobs)
        keepTriangleRuns(job);
}

void CalibrationCompletion::poseFromTriangles(std::span<const Vec3> free,
                                              std::span<const SortedTriangle> seenTriangles,
                                              const TrianglesByLongestSide& owned,
                                              std::span<TriangleJob> jobs, std::size_t f) const {
    const double tol = config_.triangleTolerance_mm;
    const double radius = kRefineRadiusFactor * config_.siteRadius_mm;
    constexpr double kDegree = std::numbers::pi / 180.0;
    const double sameView = std::cos(config_.triangleViewAngle_deg * kDegree);
    auto seenFromHere = [&](const TriangleJob& job, const RigidTransform& T_rig_from_body,
                            std::uint32_t m) {
        const Vec3& marker = job.body->markers_mm[m];
        const Vec3 viewpoint = T_rig_from_body.inverse().apply(config_.viewpoint_rig_mm);
        return seenFromNear(job.seenFrom[m], (viewpoint - marker).normalized(), sameView);
    };
    // Three points match a triangle like another object's: that object's, unless it is found in
    // this frame and they are not its markers there. Which of the frame's points lie on a body's
    // markers is found once, when first asked.
    std::vector<std::size_t> onBodyOf;
    std::vector<std::uint8_t> onBody;
    std::vector<Vec3> markersThere;
    auto onMarkersOf = [&](std::size_t b) -> const std::uint8_t* {
        const auto known = std::find(onBodyOf.begin(), onBodyOf.end(), b);
        if (known != onBodyOf.end())
            return onBody.data() + static_cast<std::size_t>(known - onBodyOf.begin()) * free.size();
        onBodyOf.push_back(b);
        onBody.resize(onBodyOf.size() * free.size(), 0);
        std::uint8_t* on = onBody.data() + (onBodyOf.size() - 1) * free.size();
        const Body& other = bodies_[b];
        markersThere.clear();
        for (const Vec3& m : other.markers_mm)
            markersThere.push_back(other.T_rig_from_body[f].apply(m));
        for (std::size_t p = 0; p < free.size(); ++p)
            on[p] = nearAny(markersThere, free[p], radius * radius) ? 1 : 0;
        return on;
    };
    auto anotherBodys = [&](const SortedTriangle& own, const SortedTriangle& seen) {
        for (std::uint32_t k = 0; k < own.alikeCount; ++k) {
            const Body& other = bodies_[own.alikeBodies[k]];
            if (!other.posed[f])
                return true;
            const std::uint8_t* on = onMarkersOf(own.alikeBodies[k]);
            if (on[seen.corners[0]] && on[seen.corners[1]] && on[seen.corners[2]])
                return true;
        }
        return false;
    };
    // Every triple of points that stands for one triangle of a body: the pose that puts the
    // most markers on points wins; two different poses that do equally well, none.
    struct Choice {
        std::size_t support = 0;
        bool tie = false;
        std::optional<RigidTransform> best;
    };
    std::vector<Choice> choices(jobs.size());
    for (const SortedTriangle& seen : seenTriangles) {
        for (const SortedTriangle& own :
             owned.within(seen.sides_mm[2] - tol, seen.sides_mm[2] + tol)) {
            TriangleJob& job = jobs[own.body];
            const Body& body = *job.body;
            if (body.posed[f] || !congruent(own, seen, tol) || anotherBodys(own, seen))
                continue;
            const std::array<Vec3, 3> from = {body.markers_mm[own.corners[0]],
                                              body.markers_mm[own.corners[1]],
                                              body.markers_mm[own.corners[2]]};
            const std::array<Vec3, 3> to = {free[seen.corners[0]], free[seen.corners[1]],
                                            free[seen.corners[2]]};
            const std::optional<RigidTransform> fit = fitTriangle(from, to);
            if (!fit || !seenFromHere(job, *fit, own.corners[0]) ||
                !seenFromHere(job, *fit, own.corners[1]) ||
                !seenFromHere(job, *fit, own.corners[2]))
                continue;
            std::size_t support = 0;
            for (const Vec3& m : body.markers_mm)
                support += nearestPoint(free, fit->apply(m), radius) != nullptr;
            Choice& choice = choices[own.body];
            if (support > choice.support) {
                choice.support = support;
                choice.best = *fit;
                choice.tie = false;
            } else if (support == choice.support && choice.best &&
                       disagreement_mm(*choice.best, *fit, job.ball) > radius) {
                choice.tie = true;
            }
        }
    }
    for (std::size_t j = 0; j < jobs.size(); ++j)
        if (choices[j].best && !choices[j].tie) {
            jobs[j].seeded[f] = 1;
            jobs[j].seed[f] = *choices[j].best;
        }
}

void CalibrationCompletion::keepTriangleRuns(TriangleJob& job) {
    // Three points that happen to fit a triangle for a frame or two pose nothing: only a run of
    // frames, posed so or by the tracker, whose poses follow on from each other as a moving body's
    // do, is taken.
    Body& body = *job.body;
    const std::size_t frames = job.seeded.size();
    auto poseAt = [&](std::size_t f) -> const RigidTransform& {
        return job.seeded[f] ? job.seed[f] : body.T_rig_from_body[f];
    };
    for (std::size_t f = 0; f < frames;) {
        if (!job.seeded[f] && !body.posed[f]) {
            ++f;
            continue;
        }
        std::size_t end = f + 1;
        while (end < frames && (job.seeded[end] || body.posed[end]) &&
               disagreement_mm(poseAt(end - 1), poseAt(end), job.ball) <=
                   config_.maxTriangleStep_mm)
            ++end;
        if (end - f >= config_.minTriangleRun)
            for (std::size_t g = f; g < end; ++g)
                if (job.seeded[g]) {
                    body.posed[g] = 1;
                    body.T_rig_from_body[g] = job.seed[g];
                    ++counters_.framesFromTriangles;
                }
        f = end;
    }
}

} // namespace edgetrack
