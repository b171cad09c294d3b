// Native Verilator testbench of a pwas-hdl design (`pwas-hdl simulate --engine native`).
//
// The design-specific part is the generated header pwas_ports.h (port members of Vtop, widths in
// 32-bit words, reset level, latency, warm-up), written by sim/pwas_native.py from manifest.json:
// nothing here names a port. The stimulus and the expected outputs (from the bit-true model) come
// from a binary job file; the replay follows sim/pwas_tb.py (the cocotb bench) cycle for cycle:
//
//   * one cycle = drive the inputs with the clock low and evaluate (combinational outputs settle),
//     sample what is transferred (valid & ready), then the rising edge;
//   * every segment starts with `reset_cycles` cycles of reset and one release cycle in which
//     nothing is offered or accepted (out.valid must be low in it);
//   * random bubbles on the source and backpressure on the sink with the run's probabilities
//     (splitmix64, seeded: reproducible; not the Python `random` sequence of the cocotb bench);
//   * `drain`: run until every expected output is seen, then latency + 3 cycles to catch extra
//     ones; otherwise reset `hold` cycles after the last input transfer (in the middle of a stream).
//
// Checked here (and again on the host from the recorded words and cycles): every output word equals
// the expected one, no output missing or extra, out.valid low after reset, latency = the manifest's
// when the sink never stalls, one transfer every PWAS_II cycles at full speed, warm (sensor top) high
// exactly from the transfer that yields the first output.
//
// Usage: pwas_native_tb JOB.bin RESULT.bin   (exit 0: every check passed, 1: some failed, 2: bad job)
// Formats: see sim/pwas_native.py (little-endian uint32 words).

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <vector>

#include "Vtop.h"
#include "verilated.h"
#include "pwas_ports.h"

namespace {

constexpr uint32_t JOB_MAGIC = 0x314a5750u;     // "PWJ1"
constexpr uint32_t RESULT_MAGIC = 0x31525750u;  // "PWR1"

enum Problem : uint32_t {
    NOT_ALL_ACCEPTED = 1u << 0,
    OUTPUT_COUNT = 1u << 1,
    TOO_MANY_BEFORE_RESET = 1u << 2,
    VALID_AFTER_RESET = 1u << 3,
    LATENCY = 1u << 4,
    INPUT_II = 1u << 5,
    OUTPUT_II = 1u << 6,
    WARM = 1u << 7,
};

// payload <-> 32-bit words, for every Verilator port type
inline void put(CData& d, const uint32_t* w) { d = static_cast<CData>(w[0]); }
inline void put(SData& d, const uint32_t* w) { d = static_cast<SData>(w[0]); }
inline void put(IData& d, const uint32_t* w) { d = w[0]; }
inline void put(QData& d, const uint32_t* w) { d = static_cast<QData>(w[0]) | (static_cast<QData>(w[1]) << 32); }
template <std::size_t N>
inline void put(VlWide<N>& d, const uint32_t* w) {
    for (std::size_t i = 0; i < N; ++i) d.m_storage[i] = w[i];
}
inline void get(const CData& d, uint32_t* w) { w[0] = d; }
inline void get(const SData& d, uint32_t* w) { w[0] = d; }
inline void get(const IData& d, uint32_t* w) { w[0] = d; }
inline void get(const QData& d, uint32_t* w) {
    w[0] = static_cast<uint32_t>(d);
    w[1] = static_cast<uint32_t>(d >> 32);
}
template <std::size_t N>
inline void get(const VlWide<N>& d, uint32_t* w) {
    for (std::size_t i = 0; i < N; ++i) w[i] = d.m_storage[i];
}

struct Rng {  // splitmix64
    uint64_t s;
    uint32_t next() {
        uint64_t z = (s += 0x9e3779b97f4a7c15ull);
        z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
        z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
        return static_cast<uint32_t>((z ^ (z >> 31)) >> 32);
    }
};

struct Reader {
    const std::vector<uint32_t>& v;
    std::size_t pos = 0;
    bool ok = true;
    uint32_t u32() {
        if (pos >= v.size()) { ok = false; return 0; }
        return v[pos++];
    }
    const uint32_t* span(std::size_t n) {
        if (pos + n > v.size()) { ok = false; return nullptr; }
        const uint32_t* p = v.data() + pos;
        pos += n;
        return p;
    }
};

struct Bench {
    Vtop* top;
    uint64_t cycle = 0;
    Rng rv{0}, rr{0};
    uint32_t pause_v = 0, pause_r = 0;  // pause if next() < threshold (0: never)
    bool src_en = true, sink_en = true;
    bool rst_active = false;
    // what the source offers
    const uint32_t* in = nullptr;
    uint32_t n_in = 0, qi = 0;
    // recorded
    std::vector<uint32_t> accepted_at, produced_at, out_words;
    std::vector<uint8_t> warm_log;
    uint32_t out_buf[PWAS_OUT_WORDS];

    void step() {
        ++cycle;
        const bool pv = pause_v && rv.next() < pause_v;  // drawn every cycle, as the cocotb drivers do
        const bool pr = pause_r && rr.next() < pause_r;
        const bool offering = src_en && qi < n_in && !pv;
        const bool accepting = sink_en && !pr;
        top->PWAS_RST = rst_active ? PWAS_RST_ON : !PWAS_RST_ON;
        top->PWAS_IN_VALID = offering;
        if (offering) put(top->PWAS_IN_DATA, in + static_cast<std::size_t>(qi) * PWAS_IN_WORDS);
        top->PWAS_OUT_READY = accepting;
        top->PWAS_CLK = 0;
        top->eval();
        if (accepting && top->PWAS_OUT_VALID) {
            get(top->PWAS_OUT_DATA, out_buf);
            out_words.insert(out_words.end(), out_buf, out_buf + PWAS_OUT_WORDS);
            produced_at.push_back(static_cast<uint32_t>(cycle));
        }
        if (offering && top->PWAS_IN_READY) {
            accepted_at.push_back(static_cast<uint32_t>(cycle));
#if PWAS_HAS_WARM
            warm_log.push_back(top->PWAS_WARM ? 1 : 0);
#endif
            ++qi;
        }
        top->PWAS_CLK = 1;
        top->eval();
    }

    bool reset(uint32_t cycles) {  // returns out.valid in the release cycle
        src_en = sink_en = false;
        rst_active = true;
        for (uint32_t i = 0; i < cycles; ++i) step();
        rst_active = false;
        step();
        const bool valid_after = top->PWAS_OUT_VALID;
        src_en = sink_en = true;
        return valid_after;
    }
};

bool read_file(const char* path, std::vector<uint32_t>& out) {
    FILE* f = std::fopen(path, "rb");
    if (!f) return false;
    std::fseek(f, 0, SEEK_END);
    long n = std::ftell(f);
    std::fseek(f, 0, SEEK_SET);
    if (n < 0 || n % 4) { std::fclose(f); return false; }
    out.resize(static_cast<std::size_t>(n) / 4);
    const bool ok = std::fread(out.data(), 4, out.size(), f) == out.size();
    std::fclose(f);
    return ok;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc < 3) {
        std::fprintf(stderr, "usage: %s JOB.bin RESULT.bin\n", argv[0]);
        return 2;
    }
    std::vector<uint32_t> job;
    if (!read_file(argv[1], job)) {
        std::fprintf(stderr, "error: cannot read the job file %s\n", argv[1]);
        return 2;
    }
    Reader rd{job};
    if (rd.u32() != JOB_MAGIC) {
        std::fprintf(stderr, "error: %s is not a pwas native job file\n", argv[1]);
        return 2;
    }
    const uint32_t reset_cycles = rd.u32();
    const uint32_t n_runs = rd.u32();

    Verilated::commandArgs(1, argv);  // no plusargs of ours reach the design
    VerilatedContext ctx;
    Vtop* top = new Vtop{&ctx};
    Bench b{top};
    top->PWAS_CLK = 1;
    top->PWAS_RST = !PWAS_RST_ON;
    top->PWAS_IN_VALID = 0;
    top->PWAS_OUT_READY = 0;
    top->eval();

    std::vector<uint32_t> res{RESULT_MAGIC, n_runs};
    uint64_t total_out = 0, total_mism = 0, total_cycles = 0;
    uint32_t any_problem = 0;
    double total_s = 0.0;
    for (uint32_t r = 0; r < n_runs && rd.ok; ++r) {
        b.pause_v = rd.u32();
        b.pause_r = rd.u32();
        const uint32_t seed_lo = rd.u32(), seed_hi = rd.u32();
        const uint64_t seed = (static_cast<uint64_t>(seed_hi) << 32) | seed_lo;
        b.rv.s = seed * 2 + 1;
        b.rr.s = seed * 2 + 7919;
        const double p_valid = 1.0 - b.pause_v / 4294967296.0, p_ready = 1.0 - b.pause_r / 4294967296.0;
        const uint32_t n_seg = rd.u32();
        const uint64_t c0 = b.cycle;
        const auto t0 = std::chrono::steady_clock::now();
        res.push_back(n_seg);
        std::size_t run_hdr = res.size();
        res.insert(res.end(), {0u, 0u, 0u, 0u});  // cycles (u64), wall time in ns (u64)
        for (uint32_t s = 0; s < n_seg && rd.ok; ++s) {
            const uint32_t n_in = rd.u32(), n_exp = rd.u32(), drain = rd.u32(), hold = rd.u32();
            const uint32_t* in = rd.span(static_cast<std::size_t>(n_in) * PWAS_IN_WORDS);
            const uint32_t* exp = rd.span(static_cast<std::size_t>(n_exp) * PWAS_OUT_WORDS);
            const uint32_t* src = rd.span(n_exp);
            if (!rd.ok) break;
            b.accepted_at.clear();
            b.produced_at.clear();
            b.out_words.clear();
            b.warm_log.clear();
            b.accepted_at.reserve(n_in);
            b.produced_at.reserve(n_exp);
            b.out_words.reserve(static_cast<std::size_t>(n_exp) * PWAS_OUT_WORDS);
            const bool valid_after = b.reset(reset_cycles);
            b.in = in;
            b.n_in = n_in;
            b.qi = 0;
            const double pv = p_valid < 0.05 ? 0.05 : p_valid, pr = p_ready < 0.05 ? 0.05 : p_ready;
            const uint64_t limit = static_cast<uint64_t>(4.0 * (static_cast<double>(n_in) * PWAS_II + PWAS_LATENCY + 8) / (pv * pr)) + 200;
            uint32_t problems = 0;
            for (uint64_t k = 0; k < limit && b.qi < n_in; ++k) b.step();
            if (b.qi < n_in) problems |= NOT_ALL_ACCEPTED;
            if (drain) {
                for (uint64_t k = 0; k < limit && b.produced_at.size() < n_exp; ++k) b.step();
                for (int k = 0; k < PWAS_LATENCY + 3; ++k) b.step();
            } else {
                for (uint32_t k = 0; k < hold; ++k) b.step();
            }
            b.n_in = 0;  // nothing more to offer until the next segment
            const uint32_t n_got = static_cast<uint32_t>(b.produced_at.size());
            const uint32_t n_cmp = n_got < n_exp ? n_got : n_exp;
            uint32_t mism = 0;
            for (uint32_t i = 0; i < n_cmp; ++i)
                if (std::memcmp(&b.out_words[static_cast<std::size_t>(i) * PWAS_OUT_WORDS], exp + static_cast<std::size_t>(i) * PWAS_OUT_WORDS,
                                4 * PWAS_OUT_WORDS) != 0)
                    ++mism;
            if (drain && n_got != n_exp) problems |= OUTPUT_COUNT;
            if (!drain && n_got > n_exp) problems |= TOO_MANY_BEFORE_RESET;
            if (valid_after) problems |= VALID_AFTER_RESET;
            const uint32_t n_acc = static_cast<uint32_t>(b.accepted_at.size());
            if (b.pause_r == 0)
                for (uint32_t i = 0; i < n_cmp; ++i)
                    if (src[i] < n_acc && b.produced_at[i] - b.accepted_at[src[i]] != static_cast<uint32_t>(PWAS_LATENCY)) {
                        problems |= LATENCY;
                        break;
                    }
            if (b.pause_r == 0 && b.pause_v == 0) {
                // II > 1 (serial architecture): the warm-up transfers are not throttled, leave them out
                const uint32_t ii = static_cast<uint32_t>(PWAS_II);
                const uint32_t a0 = ii == 1 ? 0u : std::min<uint32_t>(n_acc, static_cast<uint32_t>(PWAS_WARMUP));
                for (uint32_t i = a0 + 1; i < n_acc; ++i)
                    if (b.accepted_at[i] - b.accepted_at[i - 1] != ii) {
                        problems |= INPUT_II;
                        break;
                    }
                for (uint32_t i = 1; i < n_got; ++i)
                    if (b.produced_at[i] - b.produced_at[i - 1] != ii) {
                        problems |= OUTPUT_II;
                        break;
                    }
            }
#if PWAS_HAS_WARM
            for (std::size_t i = 0; i < b.warm_log.size(); ++i)
                if (b.warm_log[i] != (i >= static_cast<std::size_t>(PWAS_WARMUP) ? 1 : 0)) {
                    problems |= WARM;
                    break;
                }
#endif
            res.insert(res.end(), {n_acc, n_got, mism, problems, valid_after ? 1u : 0u});
            res.insert(res.end(), b.accepted_at.begin(), b.accepted_at.end());
            res.insert(res.end(), b.produced_at.begin(), b.produced_at.end());
            res.insert(res.end(), b.out_words.begin(), b.out_words.end());
            total_out += n_got;
            total_mism += mism;
            any_problem |= problems;
        }
        const uint64_t cycles = b.cycle - c0;
        const uint64_t ns = static_cast<uint64_t>(
            std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - t0).count());
        res[run_hdr] = static_cast<uint32_t>(cycles);
        res[run_hdr + 1] = static_cast<uint32_t>(cycles >> 32);
        res[run_hdr + 2] = static_cast<uint32_t>(ns);
        res[run_hdr + 3] = static_cast<uint32_t>(ns >> 32);
        total_cycles += cycles;
        total_s += ns * 1e-9;
    }
    top->final();
    delete top;
    if (!rd.ok) {
        std::fprintf(stderr, "error: the job file %s is truncated\n", argv[1]);
        return 2;
    }
    FILE* f = std::fopen(argv[2], "wb");
    if (!f || std::fwrite(res.data(), 4, res.size(), f) != res.size()) {
        std::fprintf(stderr, "error: cannot write %s\n", argv[2]);
        if (f) std::fclose(f);
        return 2;
    }
    std::fclose(f);
    const bool pass = total_mism == 0 && any_problem == 0;
    std::printf("%s: %llu outputs, %llu mismatches, problems 0x%x, %llu cycles in %.3f s\n", pass ? "PASS" : "FAIL",
                static_cast<unsigned long long>(total_out), static_cast<unsigned long long>(total_mism), any_problem,
                static_cast<unsigned long long>(total_cycles), total_s);
    return pass ? 0 : 1;
}
