// A client of fxis-shm for C++17, written from docs/protocol.md alone: libzmq through cppzmq,
// JSON through nlohmann-json (which keeps 64-bit integers exact, as the protocol's times need).
//
//   fxis::Client client("tcp://cell-pc:5555", fxis::Clock::named("realtime"));
//   client.sync_clock();                         // the service's clock against ours (section 4)
//   fxis::Tuple pair = client.tuple(t_star);     // t_star and every time returned: our clock
//   for (const fxis::Frame& f : pair.frames) { f.pixels.data(); f.stamp(); ... }
//
// Header-only; one Client per thread (a ZeroMQ socket is not thread-safe).
#pragma once

#include <time.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <fstream>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>
#include <zmq.hpp>
#include <zmq_addon.hpp>

namespace fxis {

using json = nlohmann::json;

// ---- clocks ----

// A POSIX clock read as int64 nanoseconds: the clock the caller keeps time in.
struct Clock {
    clockid_t id = CLOCK_MONOTONIC;
    std::string name = "CLOCK_MONOTONIC";

    int64_t now() const {
        timespec ts{};
        clock_gettime(id, &ts);
        return int64_t(ts.tv_sec) * 1000000000 + ts.tv_nsec;
    }

    // "monotonic", "realtime", "tai" or "boottime"
    static Clock named(const std::string& name) {
        static const std::map<std::string, std::pair<clockid_t, const char*>> clocks = {
            {"monotonic", {CLOCK_MONOTONIC, "CLOCK_MONOTONIC"}},
            {"realtime", {CLOCK_REALTIME, "CLOCK_REALTIME"}},
            {"tai", {CLOCK_TAI, "CLOCK_TAI"}},
            {"boottime", {CLOCK_BOOTTIME, "CLOCK_BOOTTIME"}},
        };
        auto found = clocks.find(name);
        if (found == clocks.end())
            throw std::invalid_argument("unknown clock '" + name + "': use monotonic, realtime, tai or boottime");
        return Clock{found->second.first, found->second.second};
    }
};

// The service's clock minus ours (protocol section 4), from the exchange with the shortest
// round trip; its error is at most round_trip_ns / 2.
struct ClockOffset {
    int64_t offset_ns = 0;
    int64_t round_trip_ns = 0;
    int exchanges = 0;
};

// ---- errors ----

// An error reply (protocol section 10): code is stable, message is for humans.
struct ServiceError : std::runtime_error {
    std::string code;
    ServiceError(std::string code_, const std::string& message)
        : std::runtime_error(code_ + ": " + message), code(std::move(code_)) {}
};

// No reply in time (the service is down, busy, or refuses our CurveZMQ keys).
struct Timeout : std::runtime_error {
    using std::runtime_error::runtime_error;
};

// A reply that does not follow the protocol.
struct ProtocolError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

// ---- CurveZMQ (protocol section 18) ----

// One key of a ZeroMQ certificate file (`fxis keys`): "public-key" or "secret-key", as Z85 text.
inline std::string read_key(const std::string& path, const std::string& which) {
    std::ifstream file(path);
    if (!file) throw std::runtime_error("cannot read the key file " + path);
    std::string line;
    while (std::getline(file, line)) {
        line.erase(0, line.find_first_not_of(" \t"));
        if (line.empty() || line[0] == '#' || line.compare(0, which.size(), which) != 0) continue;
        auto eq = line.find('=');
        if (eq == std::string::npos) continue;
        std::string key = line.substr(eq + 1);
        const char* strip = " \t\r\"'";
        key.erase(0, key.find_first_not_of(strip));
        key.erase(key.find_last_not_of(strip) + 1);
        if (key.size() != 40) throw std::runtime_error(path + ": " + which + " is not a 40-character Z85 key");
        return key;
    }
    throw std::runtime_error(path + " holds no " + which);
}

struct Keys {
    std::string server_public;  // the service's NAME.key
    std::string public_key;     // ours, from our NAME.key_secret
    std::string secret_key;

    static Keys from_files(const std::string& server_key, const std::string& client_secret) {
        return Keys{read_key(server_key, "public-key"), read_key(client_secret, "public-key"),
                    read_key(client_secret, "secret-key")};
    }
};

// ---- frames ----

inline uint64_t le64(const uint8_t* p) {
    uint64_t v = 0;
    for (int i = 7; i >= 0; --i) v = (v << 8) | p[i];
    return v;
}

inline size_t itemsize(const std::string& dtype) {
    if (dtype == "uint8") return 1;
    if (dtype == "uint16") return 2;
    if (dtype == "float32") return 4;
    throw ProtocolError("unknown dtype '" + dtype + "'");
}

struct Frame {
    std::string camera;
    int64_t frame_id = 0;
    int64_t t_capture = 0;  // our clock
    int64_t t_stored = 0;   // our clock
    int64_t t_capture_service = 0;
    int64_t generation = 0;
    std::vector<int64_t> shape;  // {height, width} or {height, width, channels}
    std::string dtype;
    zmq::message_t pixels;  // C-contiguous, row-major, little-endian (protocol section 2)

    // The frame id stamped into the pixels (protocol section 17: 8 bytes of the id and 8 of
    // its complement, little-endian, at the start of the first and of the last row), or
    // nothing if there is no valid stamp.
    std::optional<uint64_t> stamp() const {
        if (shape.size() < 2 || shape[0] < 1) return std::nullopt;
        size_t row_bytes = itemsize(dtype);
        for (size_t i = 1; i < shape.size(); ++i) row_bytes *= size_t(shape[i]);
        if (row_bytes < 16) return std::nullopt;
        const auto* data = static_cast<const uint8_t*>(pixels.data());
        const uint8_t* first = data;
        const uint8_t* last = data + (size_t(shape[0]) - 1) * row_bytes;
        if (!std::equal(first, first + 16, last)) return std::nullopt;
        uint64_t id = le64(first), inverse = le64(first + 8);
        if (inverse != ~id) return std::nullopt;
        return id;
    }
};

struct Tuple {
    int64_t t_request = 0;  // t*, our clock
    int64_t t_request_service = 0;
    int64_t skew_ns = 0;
    std::string sync;
    std::vector<Frame> frames;  // find a camera by Frame::camera, not by position
    json timing;                // the service's timing record (service clock, section 9)
};

struct Reply {
    json header;
    std::vector<zmq::message_t> buffers;
};

// ---- the client ----

class Client {
public:
    // timeout: how long to wait for a reply beyond any wait the request itself asks for.
    Client(const std::string& endpoint, Clock clock, std::chrono::milliseconds timeout = std::chrono::seconds(2),
           const Keys* keys = nullptr)
        : sock_(ctx_, zmq::socket_type::dealer), clock_(std::move(clock)), timeout_(timeout) {
        sock_.set(zmq::sockopt::linger, 0);  // close() never blocks on unsent requests
        // A DEALER with no connected peer (service down, or our CurveZMQ keys refused) blocks
        // in send: give up after the timeout instead.
        sock_.set(zmq::sockopt::sndtimeo, int(timeout_.count()));
        if (keys != nullptr) {
            sock_.set(zmq::sockopt::curve_serverkey, keys->server_public);
            sock_.set(zmq::sockopt::curve_publickey, keys->public_key);
            sock_.set(zmq::sockopt::curve_secretkey, keys->secret_key);
        }
        sock_.connect(endpoint);
    }

    const Clock& clock() const { return clock_; }
    const ClockOffset& offset() const { return offset_; }
    int64_t to_service(int64_t ours) const { return ours + offset_.offset_ns; }
    int64_t to_ours(int64_t service) const { return service - offset_.offset_ns; }

    // One request and its reply (section 12): a fresh id, [empty delimiter, header] out, the
    // reply with our id back (late replies to requests we gave up on are dropped), its buffers.
    Reply call(json request, std::chrono::milliseconds extra_wait = std::chrono::milliseconds(0)) {
        const int64_t id = next_id_++;
        request["v"] = 1;
        request["id"] = id;
        const std::string text = request.dump();
        if (!sock_.send(zmq::message_t(), zmq::send_flags::sndmore) ||
            !sock_.send(zmq::buffer(text), zmq::send_flags::none))
            throw Timeout("could not send '" + request.value("op", std::string("?")) + "': no connection");
        const auto deadline = std::chrono::steady_clock::now() + timeout_ + extra_wait;
        while (true) {
            auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline -
                                                                              std::chrono::steady_clock::now());
            zmq::pollitem_t item{sock_.handle(), 0, ZMQ_POLLIN, 0};
            if (left.count() <= 0 || zmq::poll(&item, 1, left) == 0)
                throw Timeout("no reply to '" + request.value("op", std::string("?")) + "' in time");
            std::vector<zmq::message_t> parts;
            if (!zmq::recv_multipart(sock_, std::back_inserter(parts))) continue;
            size_t head = (!parts.empty() && parts[0].size() == 0) ? 1 : 0;  // the delimiter comes back
            if (parts.size() <= head) throw ProtocolError("a reply without a header");
            json header = json::parse(parts[head].to_string_view(), nullptr, false);
            if (header.is_discarded() || !header.is_object())
                throw ProtocolError("a reply header that is not a JSON object");
            if (!header.contains("id") || header["id"] != id) continue;  // a late reply: discard
            if (header.value("v", 0) != 1) throw ProtocolError("a reply of another protocol version");
            if (!header.value("ok", false)) {
                const json& error = header.at("error");
                throw ServiceError(error.value("code", std::string("?")), error.value("message", std::string()));
            }
            Reply reply{std::move(header), {}};
            for (size_t i = head + 1; i < parts.size(); ++i) reply.buffers.push_back(std::move(parts[i]));
            return reply;
        }
    }

    // The service's clock against ours, NTP's way (section 4): `exchanges` time requests, each
    // giving offset = ((t2 - t1) + (t3 - t4)) / 2; the one with the shortest round trip wins.
    ClockOffset sync_clock(int exchanges = 8) {
        ClockOffset best;
        for (int i = 0; i < exchanges; ++i) {
            const int64_t t1 = clock_.now();
            Reply reply = call(json{{"op", "time"}});
            const int64_t t4 = clock_.now();
            const int64_t t2 = reply.header.at("received").get<int64_t>();
            const int64_t t3 = reply.header.at("now").get<int64_t>();
            const int64_t round_trip = (t4 - t1) - (t3 - t2);
            if (best.exchanges == 0 || round_trip < best.round_trip_ns) {
                best.round_trip_ns = round_trip;
                best.offset_ns = (t2 - t1) / 2 + (t3 - t4) / 2;  // halves first: no int64 overflow
            }
            best.exchanges = i + 1;
        }
        offset_ = best;
        return best;
    }

    // The frames of all (or the named) cameras chosen together for t* (section 7.4): `at` in
    // our clock, or nothing for "the moment of this call" (sent as t_call, section 4).
    Tuple tuple(std::optional<int64_t> at, const std::vector<std::string>& cameras = {},
                int64_t timeout_ms = 1000) {
        json request{{"op", "tuple"}, {"timeout_ms", timeout_ms}};
        const int64_t now_service = to_service(clock_.now());
        int64_t future_ns = 0;
        if (at) {
            request["at"] = to_service(*at);
            future_ns = std::max<int64_t>(0, to_service(*at) - now_service);
        } else {
            request["t_call"] = now_service;
        }
        if (!cameras.empty()) request["cameras"] = cameras;
        Reply reply = call(request, std::chrono::milliseconds(future_ns / 1000000 + timeout_ms));

        Tuple tuple;
        const json& h = reply.header;
        tuple.t_request_service = h.at("t_request").get<int64_t>();
        tuple.t_request = to_ours(tuple.t_request_service);
        tuple.skew_ns = h.at("skew_ns").get<int64_t>();
        tuple.sync = h.at("sync").get<std::string>();
        tuple.timing = h.value("timing", json::object());
        for (const json& meta : h.at("frames")) tuple.frames.push_back(frame(meta, reply.buffers));
        return tuple;
    }

private:
    // One entry of `frames` with its buffer, checked as section 12 says.
    Frame frame(const json& meta, std::vector<zmq::message_t>& buffers) const {
        Frame f;
        f.camera = meta.at("camera").get<std::string>();
        f.frame_id = meta.at("frame_id").get<int64_t>();
        f.t_capture_service = meta.at("t_capture").get<int64_t>();
        f.t_capture = to_ours(f.t_capture_service);
        f.t_stored = to_ours(meta.at("t_stored").get<int64_t>());
        f.generation = meta.at("generation").get<int64_t>();
        f.shape = meta.at("shape").get<std::vector<int64_t>>();
        f.dtype = meta.at("dtype").get<std::string>();
        if (meta.contains("encoding")) throw ProtocolError(f.camera + ": a compressed frame (ask for raw ones)");
        const int64_t index = meta.at("buffer").get<int64_t>();
        if (index < 0 || size_t(index) >= buffers.size())
            throw ProtocolError(f.camera + ": buffer " + std::to_string(index) + " is not in the reply");
        size_t expected = itemsize(f.dtype);
        for (int64_t n : f.shape) expected *= size_t(n);
        if (buffers[size_t(index)].size() != expected)
            throw ProtocolError(f.camera + ": a buffer of " + std::to_string(buffers[size_t(index)].size()) +
                                " bytes, its shape and dtype say " + std::to_string(expected));
        f.pixels.copy(buffers[size_t(index)]);  // a buffer may serve several frames (sequences)
        return f;
    }

    zmq::context_t ctx_;
    zmq::socket_t sock_;
    Clock clock_;
    std::chrono::milliseconds timeout_;
    int64_t next_id_ = 1;
    ClockOffset offset_;
};

}  // namespace fxis
