// Linux backend: the two IR cameras through libcamera, their frames paired by sensor timestamp.
#include "hal/linux/libcamera_camera_pair.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <dirent.h>
#include <libcamera/camera.h>
#include <libcamera/camera_manager.h>
#include <libcamera/control_ids.h>
#include <libcamera/formats.h>
#include <libcamera/framebuffer.h>
#include <libcamera/framebuffer_allocator.h>
#include <libcamera/request.h>
#include <libcamera/stream.h>
#include <sstream>
#include <string_view>
#include <sys/mman.h>
#include <unistd.h>

#include "core/simd/neon.hpp"

namespace edgetrack::linux_hal {

namespace {

/// Formats in order of preference: 8-bit luma usable in place first, then packed RGB.
struct FormatChoice {
    libcamera::PixelFormat format;
    PixelPath path;
    int bytesPerPixel;
};
const std::array<FormatChoice, 10> kFormats{{
    {libcamera::formats::R8, PixelPath::Direct, 1},
    {libcamera::formats::YUV420, PixelPath::Direct, 1},
    {libcamera::formats::NV12, PixelPath::Direct, 1},
    {libcamera::formats::NV21, PixelPath::Direct, 1},
    {libcamera::formats::BGR888, PixelPath::ConvertRgb, 3},
    {libcamera::formats::RGB888, PixelPath::ConvertRgb, 3},
    {libcamera::formats::XRGB8888, PixelPath::ConvertRgb, 4},
    {libcamera::formats::XBGR8888, PixelPath::ConvertRgb, 4},
    {libcamera::formats::ARGB8888, PixelPath::ConvertRgb, 4},
    {libcamera::formats::ABGR8888, PixelPath::ConvertRgb, 4},
}};

const FormatChoice* findFormat(const libcamera::PixelFormat& format) {
    for (const FormatChoice& choice : kFormats)
        if (choice.format == format)
            return &choice;
    return nullptr;
}

/// Request cookies carry the camera and the buffer: camera * kCookieStride + buffer.
constexpr std::uint64_t kCookieStride = 1u << 16;

hal::Nanoseconds fromMicroseconds(double us) {
    return static_cast<hal::Nanoseconds>(std::llround(us * 1e3));
}

/// Grey = (R + 2G + B) / 4 of packed RGB: the weights are symmetric in R and B, so the byte
/// order of the format does not matter. 16 pixels per step.
void rgbToGrey(const std::uint8_t* in, int bytesPerPixel, int width, std::uint8_t* out) {
    int x = 0;
    if (bytesPerPixel == 3) {
        for (; x + 16 <= width; x += 16) {
            const uint8x16x3_t rgb = vld3q_u8(in + 3 * x);
            vst1q_u8(out + x, vhaddq_u8(vhaddq_u8(rgb.val[0], rgb.val[2]), rgb.val[1]));
        }
    } else {
        for (; x + 16 <= width; x += 16) {
            const uint8x16x4_t rgba = vld4q_u8(in + 4 * x);
            vst1q_u8(out + x, vhaddq_u8(vhaddq_u8(rgba.val[0], rgba.val[2]), rgba.val[1]));
        }
    }
    for (; x < width; ++x) {
        const std::uint8_t* p = in + bytesPerPixel * x;
        const unsigned outer = (unsigned{p[0]} + p[2]) >> 1;
        out[x] = static_cast<std::uint8_t>((outer + p[1]) >> 1);
    }
}

/// \return true when this process holds a V4L2 or media device node that has been deleted.
bool holdsDeletedVideoNode() {
    DIR* dir = ::opendir("/proc/self/fd");
    if (dir == nullptr)
        return false;
    bool deleted = false;
    while (const dirent* entry = ::readdir(dir)) {
        char target[256];
        const ssize_t n = ::readlinkat(::dirfd(dir), entry->d_name, target, sizeof target - 1);
        if (n <= 0)
            continue;
        const std::string_view link(target, static_cast<std::size_t>(n));
        if ((link.starts_with("/dev/video") || link.starts_with("/dev/media") ||
             link.starts_with("/dev/v4l-subdev")) &&
            link.ends_with(" (deleted)")) {
            deleted = true;
            break;
        }
    }
    ::closedir(dir);
    return deleted;
}

} // namespace

LibcameraCameraPair::LibcameraCameraPair(LibcameraPairConfig config)
    : config_(std::move(config)) {
    framePeriod_ = static_cast<hal::Nanoseconds>(std::llround(1e9 / config_.frameRate_hz));
    pairTolerance_ = fromMicroseconds(config_.pairTolerance_us);
    manager_ = std::make_unique<libcamera::CameraManager>();
    if (const int ret = manager_->start(); ret < 0) {
        errorText_ =
            std::string("libcamera's camera manager did not start: ") + std::strerror(-ret);
        return;
    }
    managerStarted_ = true;
    slots_.resize(static_cast<std::size_t>(config_.buffers));
    for (Side& side : sides_)
        side.completed = RingBuffer<Completed>(static_cast<std::size_t>(config_.buffers));
}

LibcameraCameraPair::~LibcameraCameraPair() {
    stop();
    if (!abandoned_.empty()) {
        // Stopping the manager would stop the removed camera and abort: leave all of it to the
        // end of the process.
        (void)manager_.release();
        for (Side& side : abandoned_)
            (void)new Side(std::move(side));
        return;
    }
    if (managerStarted_)
        manager_->stop();
}

std::vector<std::string> LibcameraCameraPair::cameraIds() const {
    std::vector<std::string> ids;
    if (managerStarted_)
        for (const std::shared_ptr<libcamera::Camera>& camera : manager_->cameras())
            ids.push_back(camera->id());
    return ids;
}

Status LibcameraCameraPair::start() {
    if (!managerStarted_)
        return Error{errorText_};
    stop();
    if (!abandoned_.empty()) {
        errorText_ = "a camera's device was removed while streaming and libcamera cannot take it "
                     "back in this process: restart edgetrack";
        return Error{errorText_};
    }
    for (int index = 0; index < 2; ++index) {
        if (Status s = startSide(index); !s) {
            stopSides();
            errorText_ = s.error().message;
            return s;
        }
    }
    {
        std::lock_guard lock(mutex_);
        streaming_ = true;
        failed_ = false;
        sequenceToNumber_.reset();
        for (Side& side : sides_)
            side.lastCompletion = clock_.now();
    }
    for (int index = 0; index < 2; ++index) {
        Side& side = sides_[static_cast<std::size_t>(index)];
        if (const int ret = side.camera->start(side.startControls.get()); ret < 0) {
            stop();
            errorText_ = "camera " + std::to_string(index) + " '" +
                         config_.ids[static_cast<std::size_t>(index)] +
                         "' did not start streaming: " + std::strerror(-ret);
            return Error{errorText_};
        }
        side.started = true;
    }
    std::lock_guard lock(mutex_);
    for (int index = 0; index < 2; ++index)
        for (std::size_t b = 0; b < sides_[static_cast<std::size_t>(index)].requests.size(); ++b)
            requeue(index, static_cast<int>(b));
    if (failed_) {
        errorText_ = "a camera refused its first requests";
        return Error{errorText_};
    }
    return Ok{};
}

Status LibcameraCameraPair::startSide(int index) {
    Side& side = sides_[static_cast<std::size_t>(index)];
    const std::string& id = config_.ids[static_cast<std::size_t>(index)];
    const std::string name = "camera " + std::to_string(index) + " '" + id + "'";
    side.camera = manager_->get(id);
    if (!side.camera) {
        std::string known;
        for (const std::string& other : cameraIds())
            known += (known.empty() ? "" : ", ") + ("'" + other + "'");
        return Error{name + " not found (libcamera lists " + (known.empty() ? "none" : known) +
                     ")"};
    }
    if (const int ret = side.camera->acquire(); ret < 0)
        return Error{name + " cannot be acquired: " + std::strerror(-ret) +
                     (ret == -EBUSY ? " (another program uses it)" : "")};
    side.acquired = true;

    side.configuration = side.camera->generateConfiguration({libcamera::StreamRole::Viewfinder});
    if (!side.configuration || side.configuration->empty())
        return Error{name + " offers no stream"};
    libcamera::StreamConfiguration& stream = side.configuration->at(0);
    const std::vector<libcamera::PixelFormat> offered = stream.formats().pixelformats();
    const FormatChoice* choice = nullptr;
    for (const FormatChoice& candidate : kFormats)
        if (std::find(offered.begin(), offered.end(), candidate.format) != offered.end()) {
            choice = &candidate;
            break;
        }
    if (choice == nullptr) {
        std::string list;
        for (const libcamera::PixelFormat& f : offered)
            list += " " + f.toString();
        return Error{name + " offers no 8-bit grey, YUV or RGB format (offers" + list + ")"};
    }
    stream.pixelFormat = choice->format;
    stream.size = libcamera::Size(static_cast<unsigned>(config_.width_px),
                                  static_cast<unsigned>(config_.height_px));
    stream.bufferCount = static_cast<unsigned>(config_.buffers);
    if (side.configuration->validate() == libcamera::CameraConfiguration::Invalid)
        return Error{name + " refuses " + stream.toString()};
    if (stream.size.width != static_cast<unsigned>(config_.width_px) ||
        stream.size.height != static_cast<unsigned>(config_.height_px))
        return Error{name + " gives " + stream.size.toString() + ", not " +
                     std::to_string(config_.width_px) + "x" + std::to_string(config_.height_px) +
                     " (the size the stereo calibration is for)"};
    choice = findFormat(stream.pixelFormat);
    if (choice == nullptr)
        return Error{name + " changed the format to " + stream.pixelFormat.toString()};
    if (const int ret = side.camera->configure(side.configuration.get()); ret < 0)
        return Error{name + " cannot be configured as " + stream.toString() + ": " +
                     std::strerror(-ret)};
    side.stream = stream.stream();
    side.path = choice->path;
    side.bytesPerPixel = choice->bytesPerPixel;
    side.stride_bytes = static_cast<int>(stream.stride);

    side.allocator = std::make_unique<libcamera::FrameBufferAllocator>(side.camera);
    if (const int ret = side.allocator->allocate(side.stream); ret <= 0)
        return Error{name + ": no buffers (" + std::strerror(ret < 0 ? -ret : ENOMEM) + ")"};
    const std::vector<std::unique_ptr<libcamera::FrameBuffer>>& buffers =
        side.allocator->buffers(side.stream);
    const std::size_t count = std::min(buffers.size(), slots_.size());
    for (std::size_t b = 0; b < count; ++b) {
        const libcamera::FrameBuffer::Plane& plane = buffers[b]->planes()[0];
        const std::size_t length = plane.offset + plane.length;
        void* base = ::mmap(nullptr, length, PROT_READ, MAP_SHARED, plane.fd.get(), 0);
        if (base == MAP_FAILED)
            return Error{name + ": cannot map buffer " + std::to_string(b) + ": " +
                         std::strerror(errno)};
        side.mapped.push_back(
            MappedBuffer{base, length, static_cast<const std::uint8_t*>(base) + plane.offset});
        if (side.path == PixelPath::ConvertRgb)
            side.grey.emplace_back(static_cast<std::size_t>(config_.width_px) *
                                   static_cast<std::size_t>(config_.height_px));
        std::unique_ptr<libcamera::Request> request =
            side.camera->createRequest(static_cast<std::uint64_t>(index) * kCookieStride + b);
        if (!request || request->addBuffer(side.stream, buffers[b].get()) < 0)
            return Error{name + ": cannot create request " + std::to_string(b)};
        side.requests.push_back(std::move(request));
    }
    side.camera->requestCompleted.connect(
        this, [this, index](libcamera::Request* request) { onRequestCompleted(index, request); });
    side.camera->disconnected.connect(this, [this, index]() { onDisconnected(index); });

    // Frame rate and a fixed exposure where the sensor has the controls (vimc has neither).
    libcamera::ControlList controls(side.camera->controls());
    const libcamera::ControlInfoMap& info = side.camera->controls();
    if (info.count(&libcamera::controls::AeEnable) != 0)
        controls.set(libcamera::controls::AeEnable, false);
    if (info.count(&libcamera::controls::ExposureTime) != 0)
        controls.set(libcamera::controls::ExposureTime,
                     static_cast<std::int32_t>(std::lround(config_.exposure_us)));
    if (info.count(&libcamera::controls::FrameDurationLimits) != 0) {
        const std::int64_t period_us = framePeriod_ / 1000;
        const std::array<std::int64_t, 2> limits{period_us, period_us};
        controls.set(libcamera::controls::FrameDurationLimits,
                     libcamera::Span<const std::int64_t, 2>(limits));
    }
    side.startControls = std::make_unique<libcamera::ControlList>(std::move(controls));
    return Ok{};
}

void LibcameraCameraPair::stop() {
    {
        std::lock_guard lock(mutex_);
        streaming_ = false;
    }
    stopSides();
}

void LibcameraCameraPair::stopSides() {
    for (Side& side : sides_) {
        if (side.camera) {
            side.camera->requestCompleted.disconnect(this);
            side.camera->disconnected.disconnect(this);
        }
        if (side.removed) {
            // libcamera 0.0.3 aborts when a camera whose device is gone is stopped: keep all of
            // it alive, unstopped, until the process ends (see needsProcessRestart()).
            abandoned_.push_back(std::move(side));
        } else {
            if (side.started)
                side.camera->stop(); // cancels the queued requests
            side.requests.clear();   // before the allocator frees their buffers
            for (const MappedBuffer& m : side.mapped)
                ::munmap(m.base, m.length);
            side.allocator.reset();
            if (side.acquired)
                side.camera->release();
        }
        side = Side{};
        side.completed = RingBuffer<Completed>(slots_.size());
    }
    std::lock_guard lock(mutex_);
    for (PairSlot& slot : slots_)
        slot = PairSlot{};
    failed_ = false;
}

void LibcameraCameraPair::requeue(int index, int buffer) {
    Side& side = sides_[static_cast<std::size_t>(index)];
    libcamera::Request* request = side.requests[static_cast<std::size_t>(buffer)].get();
    request->reuse(libcamera::Request::ReuseBuffers);
    if (side.camera->queueRequest(request) < 0)
        failed_ = true;
}

void LibcameraCameraPair::onRequestCompleted(int index, libcamera::Request* request) {
    std::lock_guard lock(mutex_);
    if (!streaming_)
        return; // cancelled by stop()
    Side& side = sides_[static_cast<std::size_t>(index)];
    side.lastCompletion = clock_.now();
    const int buffer = static_cast<int>(request->cookie() % kCookieStride);
    const libcamera::FrameBuffer* frameBuffer = request->findBuffer(side.stream);
    if (request->status() == libcamera::Request::RequestCancelled) {
        // Cancelled while streaming: the pipeline stopped under us (device gone or broken).
        ++libcameraCounters_.failedRequests;
        side.faulted = true;
        failed_ = true;
        frameArrived_.notify_all();
        return;
    }
    if (frameBuffer == nullptr ||
        frameBuffer->metadata().status != libcamera::FrameMetadata::FrameSuccess) {
        ++libcameraCounters_.failedRequests;
        requeue(index, buffer);
        return;
    }
    const libcamera::FrameMetadata& metadata = frameBuffer->metadata();
    const std::optional<std::int64_t> sensorTime =
        request->metadata().get(libcamera::controls::SensorTimestamp);
    const std::optional<std::int32_t> exposure_us =
        request->metadata().get(libcamera::controls::ExposureTime);
    Completed completed;
    completed.buffer = buffer;
    hal::CameraFrame& timing = completed.frame;
    timing.width_px = config_.width_px;
    timing.height_px = config_.height_px;
    timing.exposureStart =
        sensorTime ? *sensorTime : static_cast<hal::Nanoseconds>(metadata.timestamp);
    timing.exposureEnd =
        timing.exposureStart + (exposure_us ? hal::Nanoseconds{*exposure_us} * 1000
                                            : fromMicroseconds(config_.exposure_us));
    timing.sequence = metadata.sequence;
    if (side.sequenceKnown && timing.sequence > side.lastSequence + 1)
        counters_.droppedNoBuffer += timing.sequence - side.lastSequence - 1;
    side.sequenceKnown = true;
    side.lastSequence = timing.sequence;
    // At most one entry per buffer, so the ring (one slot per buffer) cannot overflow.
    side.completed.tryPush(completed);
    frameArrived_.notify_all();
}

void LibcameraCameraPair::onDisconnected(int index) {
    std::lock_guard lock(mutex_);
    sides_[static_cast<std::size_t>(index)].faulted = true;
    failed_ = true;
    frameArrived_.notify_all();
}

void LibcameraCameraPair::checkForRemovedCamera() {
    const hal::Nanoseconds now = clock_.now();
    const hal::Nanoseconds silence =
        std::max(10 * framePeriod_, 250 * hal::kNanosecondsPerMillisecond);
    const auto suspect = [&](const Side& side) {
        return side.faulted || now - side.lastCompletion > silence;
    };
    if (!suspect(sides_[0]) && !suspect(sides_[1]))
        return;
    if (!holdsDeletedVideoNode())
        return;
    for (Side& side : sides_)
        if (suspect(side)) {
            side.removed = true;
            failed_ = true;
        }
}

hal::AcquireStatus LibcameraCameraPair::fail() {
    checkForRemovedCamera();
    ++counters_.failures;
    return hal::AcquireStatus::Failed;
}

LibcameraCameraPair::Completed LibcameraCameraPair::popCompleted(int index) {
    Side& side = sides_[static_cast<std::size_t>(index)];
    Completed front;
    side.completed.pop(front);
    return front;
}

hal::AcquireStatus LibcameraCameraPair::acquire(hal::StereoFrame& frame, hal::Nanoseconds timeout) {
    std::unique_lock lock(mutex_);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::nanoseconds(timeout);
    std::array<Completed, 2> pair{};
    int slotIndex = -1;
    bool timedOut = false;
    for (;;) {
        if (!streaming_)
            return hal::AcquireStatus::Stopped;
        if (failed_)
            return fail();
        while (!sides_[0].completed.empty() && !sides_[1].completed.empty()) {
            const hal::Nanoseconds midA = sides_[0].completed.front().frame.midExposure();
            const hal::Nanoseconds midB = sides_[1].completed.front().frame.midExposure();
            if (std::abs(midA - midB) <= pairTolerance_) {
                pair = {popCompleted(0), popCompleted(1)};
                break;
            }
            const int older = midA < midB ? 0 : 1;
            requeue(older, popCompleted(older).buffer);
            ++counters_.droppedUnpaired;
        }
        if (pair[0].buffer >= 0)
            break;
        if (timedOut || timeout <= 0) {
            checkForRemovedCamera();
            return failed_ ? fail() : hal::AcquireStatus::Timeout;
        }
        // One more look at the state and the queues after the wait, whatever ended it.
        timedOut = frameArrived_.wait_until(lock, deadline) == std::cv_status::timeout;
    }
    for (std::size_t s = 0; s < slots_.size(); ++s)
        if (!slots_[s].inUse) {
            slotIndex = static_cast<int>(s);
            break;
        }
    // Each camera has slots_.size() buffers, so a pair always finds a free slot.
    PairSlot& slot = slots_[static_cast<std::size_t>(slotIndex)];
    slot.inUse = true;
    slot.buffer = {pair[0].buffer, pair[1].buffer};
    ++counters_.delivered;
    if (sides_[0].path == PixelPath::ConvertRgb || sides_[1].path == PixelPath::ConvertRgb)
        ++libcameraCounters_.converted;
    // Numbered by camera 0's sensor sequence: an exposure that was dropped or left unpaired
    // leaves a gap, as the HAL promises. The first pair after start(), or a sequence that went
    // back, continues from the next number, so numbers only grow.
    const auto sequence = static_cast<std::int64_t>(pair[0].frame.sequence);
    const auto next = static_cast<std::int64_t>(nextNumber_);
    if (!sequenceToNumber_ || sequence + *sequenceToNumber_ < next)
        sequenceToNumber_ = next - sequence;
    frame.number = static_cast<std::uint64_t>(sequence + *sequenceToNumber_);
    nextNumber_ = frame.number + 1;
    frame.slot = slotIndex;
    lock.unlock();

    // The buffers belong to the consumer until release(): converting needs no lock.
    for (std::size_t c = 0; c < 2; ++c) {
        Side& side = sides_[c];
        const int buffer = pair[c].buffer;
        hal::CameraFrame& out = frame.camera[c];
        out = pair[c].frame;
        if (side.path == PixelPath::Direct) {
            out.pixels = side.mapped[static_cast<std::size_t>(buffer)].pixels;
            out.stride_bytes = side.stride_bytes;
        } else {
            convertToGrey(side, buffer);
            out.pixels = side.grey[static_cast<std::size_t>(buffer)].data();
            out.stride_bytes = config_.width_px;
        }
    }
    return hal::AcquireStatus::Frame;
}

void LibcameraCameraPair::convertToGrey(Side& side, int buffer) {
    const std::uint8_t* in = side.mapped[static_cast<std::size_t>(buffer)].pixels;
    std::uint8_t* out = side.grey[static_cast<std::size_t>(buffer)].data();
    for (int y = 0; y < config_.height_px; ++y)
        rgbToGrey(in + static_cast<std::ptrdiff_t>(y) * side.stride_bytes, side.bytesPerPixel,
                  config_.width_px, out + static_cast<std::ptrdiff_t>(y) * config_.width_px);
}

void LibcameraCameraPair::release(const hal::StereoFrame& frame) {
    std::lock_guard lock(mutex_);
    if (!streaming_ || frame.slot < 0 || static_cast<std::size_t>(frame.slot) >= slots_.size())
        return; // stopped since: the buffers went with the stream
    PairSlot& slot = slots_[static_cast<std::size_t>(frame.slot)];
    if (!slot.inUse)
        return;
    slot.inUse = false;
    requeue(0, slot.buffer[0]);
    requeue(1, slot.buffer[1]);
}

bool LibcameraCameraPair::needsProcessRestart() const {
    std::lock_guard lock(mutex_);
    return !abandoned_.empty() || sides_[0].removed || sides_[1].removed;
}

hal::CameraPairCounters LibcameraCameraPair::counters() const {
    std::lock_guard lock(mutex_);
    return counters_;
}

LibcameraPairCounters LibcameraCameraPair::libcameraCounters() const {
    std::lock_guard lock(mutex_);
    return libcameraCounters_;
}

std::string LibcameraCameraPair::describe() const {
    std::ostringstream text;
    for (std::size_t c = 0; c < 2; ++c) {
        const Side& side = sides_[c];
        text << (c == 0 ? "" : "; ") << "camera " << c << " '" << config_.ids[c] << "'";
        if (side.configuration && !side.configuration->empty())
            text << " " << side.configuration->at(0).toString()
                 << (side.path == PixelPath::Direct ? " (luma in place)" : " (RGB to grey)");
        else
            text << " not started";
    }
    return text.str();
}

} // namespace edgetrack::linux_hal
