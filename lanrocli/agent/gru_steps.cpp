// An update's reading of its sentences (lanrocli/agent/encoder.py's encode, gru.py's read_sentences,
// forward_steps and backward_steps) in C++, for CPU tensors: one call forward, one backward.
//
// The Python makes about fifteen small tensor operations a word forward and eight backward, and on a batch
// of a few dozen short sentences each costs more in dispatch and allocation than in arithmetic. Here a
// step's element-wise work is plain loops into buffers allocated once a call, and ATen is called only for
// what is not plain IEEE arithmetic (the matrix products, the sigmoids, index_add_), on tensors of the shapes
// and layouts the Python gives them. The loops apply each addition, subtraction and multiplication in the
// Python's order, with its roundings: compiled with -ffp-contract=off so that none is fused, but for the two
// that ATen's addcmul fuses on CPU (std::fma here). So the results are the Python's bit for bit;
// tests/agent/test_native.py holds them to it, on the machine that runs the tests.

#include <ATen/ATen.h>
#include <torch/library.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

namespace {

// Scratch for the steps: one buffer whose first members * rows * width elements are viewed as a contiguous
// [members, rows, width] tensor, the layout the Python's fresh tensors of that shape have.
class Scratch {
 public:
  Scratch(int64_t members, int64_t rows, int64_t width, const at::TensorOptions& options)
      : members_(members), width_(width), buffer_(at::empty({members * rows * width}, options)) {}
  at::Tensor rows(int64_t k) const { return buffer_.as_strided({members_, k, width_}, {k * width_, width_, 1}); }

 private:
  int64_t members_, width_;
  at::Tensor buffer_;
};

template <typename T>
std::vector<at::Tensor> forward_typed(const at::Tensor& inputs_any, const at::Tensor& weight_hh,
                                      const at::Tensor& bias_hh, at::IntArrayRef active, int64_t trained, bool keep) {
  const at::Tensor inputs = inputs_any.contiguous();
  const int64_t members = inputs.size(0), packed = inputs.size(1), gates = inputs.size(2), size = gates / 3;
  const int64_t rows = active[0];
  const at::Tensor weight_t = weight_hh.transpose(1, 2), bias = bias_hh.unsqueeze(1);
  const auto options = inputs.options();
  at::Tensor last = at::empty({members, rows, size}, options);
  // What the backward pass needs of the first `trained` members, packed as the inputs are.
  const int64_t kept = keep ? trained : 0;
  at::Tensor before = at::empty({kept, packed, size}, options), rz_kept = at::empty({kept, packed, 2 * size}, options);
  at::Tensor n_kept = at::empty({kept, packed, size}, options), hidden_n_kept = at::empty({kept, packed, size}, options);
  const Scratch hidden_s(members, rows, gates, options), rz_in_s(members, rows, 2 * size, options);
  const Scratch rz_s(members, rows, 2 * size, options), n_in_s(members, rows, size, options);
  const Scratch sig_s(members, rows, size, options);
  const Scratch h_s[2] = {Scratch(members, rows, size, options), Scratch(members, rows, size, options)};
  at::Tensor h = h_s[0].rows(rows).zero_();
  const T* x_all = inputs.data_ptr<T>();
  T *before_p = before.data_ptr<T>(), *rz_kept_p = rz_kept.data_ptr<T>(), *n_kept_p = n_kept.data_ptr<T>();
  T* hidden_n_kept_p = hidden_n_kept.data_ptr<T>();
  T* last_p = last.data_ptr<T>();
  std::vector<T> n_spare(size);  // a row's n where it is not kept
  int64_t start = 0, width = rows;  // width: the rows of h, those that read a word at the step before
  for (size_t t = 0; t < active.size(); ++t) {
    const int64_t k = active[t];
    const T* h_p = h.data_ptr<T>();
    for (int64_t m = 0; m < members; ++m) {  // rows k to width: sentences that have ended, their state final
      for (int64_t i = k; i < width; ++i) {
        for (int64_t j = 0; j < size; ++j) last_p[(m * rows + i) * size + j] = h_p[(m * width + i) * size + j];
      }
    }
    const at::Tensor h_read = k < width ? h.slice(1, 0, k) : h;
    at::Tensor hidden = hidden_s.rows(k), rz_in = rz_in_s.rows(k), rz = rz_s.rows(k), n_in = n_in_s.rows(k);
    at::Tensor sig = sig_s.rows(k), h_next = h_s[(t + 1) % 2].rows(k);
    at::baddbmm_out(hidden, bias, h_read, weight_t);  // [members, k, 3 * size]
    const T* hid = hidden.data_ptr<T>();
    T* __restrict__ rz_in_p = rz_in.data_ptr<T>();
    for (int64_t m = 0; m < members; ++m) {
      for (int64_t i = 0; i < k; ++i) {
        const T* x = x_all + (m * packed + start + i) * gates;
        const T* hd = hid + (m * k + i) * gates;
        for (int64_t j = 0; j < 2 * size; ++j) rz_in_p[(m * k + i) * 2 * size + j] = x[j] + hd[j];
      }
    }
    at::sigmoid_out(rz, rz_in);
    const T* rz_p = rz.data_ptr<T>();
    T* __restrict__ n_in_p = n_in.data_ptr<T>();  // 2 (x W_in + b_in + r * (h W_hn + b_hn))
    for (int64_t m = 0; m < members; ++m) {
      for (int64_t i = 0; i < k; ++i) {
        const int64_t row = m * k + i, packed_row = m * packed + start + i;
        const T* x = x_all + packed_row * gates + 2 * size;
        const T* hn = hid + row * gates + 2 * size;
        const T* r = rz_p + row * 2 * size;
        for (int64_t j = 0; j < size; ++j) n_in_p[row * size + j] = std::fma(r[j], hn[j], x[j]) * T(2);
        if (m < kept) {
          for (int64_t j = 0; j < 2 * size; ++j) rz_kept_p[packed_row * 2 * size + j] = r[j];
          for (int64_t j = 0; j < size; ++j) hidden_n_kept_p[packed_row * size + j] = hn[j];
          for (int64_t j = 0; j < size; ++j) before_p[packed_row * size + j] = h_p[(m * width + i) * size + j];
        }
      }
    }
    at::sigmoid_out(sig, n_in);  // tanh(v) = 2 sigmoid(2v) - 1, as gru.py's _tanh
    const T* sig_p = sig.data_ptr<T>();
    T* __restrict__ next_p = h_next.data_ptr<T>();
    for (int64_t m = 0; m < members; ++m) {
      for (int64_t i = 0; i < k; ++i) {
        const int64_t row = m * k + i;
        const T* h_row = h_p + (m * width + i) * size;
        const T* z = rz_p + row * 2 * size + size;
        T* __restrict__ n = m < kept ? n_kept_p + (m * packed + start + i) * size : n_spare.data();
        for (int64_t j = 0; j < size; ++j) {
          n[j] = sig_p[row * size + j] * T(2) - T(1);
          next_p[row * size + j] = std::fma(z[j], h_row[j] - n[j], n[j]);
        }
      }
    }
    start += k;
    h = h_next;
    width = k;
  }
  last.slice(1, 0, width).copy_(h);
  if (!keep) return {last};
  return {last, before, rz_kept, n_kept, hidden_n_kept};
}

// Returns the gradients of the members' inputs; writes those of their recurrent weights and biases into
// grad_weight and grad_bias.
template <typename T>
at::Tensor backward_typed(const at::Tensor& grad_any, const at::Tensor& weight_hh, const at::Tensor& before_any,
                          const at::Tensor& rz_any, const at::Tensor& n_any, const at::Tensor& hidden_n_any,
                          at::IntArrayRef active, at::Tensor grad_weight, at::Tensor grad_bias) {
  const int64_t members = weight_hh.size(0);
  const at::Tensor grad = grad_any.slice(0, 0, members).contiguous();
  const at::Tensor before = before_any.contiguous(), rz = rz_any.contiguous(), n_all = n_any.contiguous();
  const at::Tensor hidden_n = hidden_n_any.contiguous();
  const int64_t packed = before.size(1), size = before.size(2), rows = grad.size(1);
  const int64_t steps = static_cast<int64_t>(active.size());
  const auto options = before.options();
  // What does not depend on the incoming gradient, for all steps at once: the derivatives of h' with
  // respect to the recurrent gate inputs h W_h + b_h (r, z, n), and to n's pre-activation.
  at::Tensor to_n = at::empty({members, packed, size}, options);
  at::Tensor to_hidden = at::empty({members, packed, 3 * size}, options);
  {
    const T *b = before.data_ptr<T>(), *rz_p = rz.data_ptr<T>(), *n_p = n_all.data_ptr<T>();
    const T* hn = hidden_n.data_ptr<T>();
    T* __restrict__ to_n_p = to_n.data_ptr<T>();
    T* __restrict__ to_h = to_hidden.data_ptr<T>();
    for (int64_t row = 0; row < members * packed; ++row) {
      for (int64_t j = 0; j < size; ++j) {
        const T r = rz_p[row * 2 * size + j], z = rz_p[row * 2 * size + size + j], n = n_p[row * size + j];
        const T squared = n * n;
        const T t_n = (T(1) - z) * (T(1) - squared);
        const T a = t_n * hn[row * size + j];
        const T a_r = a * r;
        to_h[row * 3 * size + j] = a_r * (T(1) - r);
        const T gap = b[row * size + j] - n;
        const T gap_z = gap * z;
        to_h[row * 3 * size + size + j] = gap_z * (T(1) - z);
        to_h[row * 3 * size + 2 * size + j] = t_n * r;
        to_n_p[row * size + j] = t_n;
      }
    }
  }
  std::vector<int64_t> ends(steps);
  int64_t total = 0;
  for (int64_t t = 0; t < steps; ++t) ends[t] = (total += active[t]);
  at::Tensor hidden_all = at::empty({members, packed, 3 * size}, options);  // gradients of h W_h + b_h
  at::Tensor grad_inputs = at::empty({members, packed, 3 * size}, options);
  const Scratch step_s(members, rows, 3 * size, options), g_z_s(members, rows, size, options);
  const Scratch product_s(members, rows, size, options), joined_s(members, rows, size, options);
  // The gradient with respect to the state after step t, rows of `g_width` values.
  const T* grad_p = grad.data_ptr<T>();
  const T* g_p = grad_p;
  int64_t g_stride = rows * size;  // between members
  const T *rz_p = rz.data_ptr<T>(), *to_h = to_hidden.data_ptr<T>();
  const T* to_n_p = to_n.data_ptr<T>();
  T* __restrict__ all_p = hidden_all.data_ptr<T>();
  T* __restrict__ in_p = grad_inputs.data_ptr<T>();
  for (int64_t t = steps - 1; t >= 0; --t) {
    const int64_t k = active[t], from = ends[t] - k;
    at::Tensor step = step_s.rows(k), g_z = g_z_s.rows(k), product = product_s.rows(k);
    T* __restrict__ step_p = step.data_ptr<T>();
    T* __restrict__ g_z_p = g_z.data_ptr<T>();
    for (int64_t m = 0; m < members; ++m) {
      for (int64_t i = 0; i < k; ++i) {
        const int64_t row = m * packed + from + i;
        const T* gr = g_p + m * g_stride + i * size;
        for (int64_t q = 0; q < 3; ++q) {
          for (int64_t j = 0; j < size; ++j) {
            const T value = to_h[row * 3 * size + q * size + j] * gr[j];
            step_p[(m * k + i) * 3 * size + q * size + j] = value;
            all_p[row * 3 * size + q * size + j] = value;
          }
        }
        for (int64_t j = 0; j < 2 * size; ++j) in_p[row * 3 * size + j] = all_p[row * 3 * size + j];
        for (int64_t j = 0; j < size; ++j) {
          g_z_p[(m * k + i) * size + j] = gr[j] * rz_p[row * 2 * size + size + j];
          in_p[row * 3 * size + 2 * size + j] = gr[j] * to_n_p[row * size + j];
        }
      }
    }
    at::baddbmm_out(product, g_z, step, weight_hh);  // with respect to h before the step
    g_p = product.data_ptr<T>();
    g_stride = k * size;
    if (t > 0 && active[t - 1] > k) {  // rows whose sentence ended at step t - 1 join
      const int64_t wide = active[t - 1];
      T* joined_p = joined_s.rows(wide).data_ptr<T>();
      for (int64_t m = 0; m < members; ++m) {
        for (int64_t i = 0; i < wide; ++i) {
          const T* source = i < k ? g_p + (m * k + i) * size : grad_p + (m * rows + i) * size;
          for (int64_t j = 0; j < size; ++j) joined_p[(m * wide + i) * size + j] = source[j];
        }
      }
      g_p = joined_p;
      g_stride = wide * size;
    }
  }
  at::bmm_out(grad_weight, hidden_all.transpose(1, 2), before);
  at::sum_out(grad_bias, hidden_all, 1);
  return grad_inputs;
}

// A batch's sentences as the Python's encode orders them: its distinct rows, each row's distinct row
// (`inverse`), and the distinct rows' order for reading, longest first (`order`, ties in distinct order).
struct Sentences {
  std::vector<int64_t> first;    // a row holding each distinct sentence, in encode's order of them
  std::vector<int64_t> inverse;  // per row, its distinct sentence
  std::vector<int64_t> lengths;  // per distinct sentence, its words
  std::vector<int64_t> order;    // distinct sentences longest first, ties kept in order
};

Sentences find_sentences(const at::Tensor& tokens, int64_t pad_id, int64_t vocab_size) {
  const int64_t rows = tokens.size(0), length = tokens.size(1);
  const int64_t* ids = tokens.data_ptr<int64_t>();
  // encode's _distinct orders sentences as numbers in base vocab_size, the last word most significant,
  // where they fit in 63 bits, and as rows of words, the first word first, where they do not.
  bool as_numbers = true;
  for (int64_t i = 0, power = 1; i < length && as_numbers; ++i) {
    as_numbers = power <= INT64_MAX / vocab_size;  // vocab_size ** (i + 1) < 2 ** 63
    power = as_numbers ? power * vocab_size : power;
  }
  auto before = [&](int64_t a, int64_t b) {
    for (int64_t i = 0; i < length; ++i) {
      const int64_t at_i = as_numbers ? length - 1 - i : i;
      const int64_t x = ids[a * length + at_i], y = ids[b * length + at_i];
      if (x != y) return x < y;
    }
    return false;
  };
  std::vector<int64_t> sorted(rows);
  for (int64_t r = 0; r < rows; ++r) sorted[r] = r;
  std::stable_sort(sorted.begin(), sorted.end(), before);
  Sentences found;
  found.inverse.resize(rows);
  for (int64_t j = 0; j < rows; ++j) {
    if (j == 0 || before(sorted[j - 1], sorted[j])) found.first.push_back(sorted[j]);
    found.inverse[sorted[j]] = static_cast<int64_t>(found.first.size()) - 1;
  }
  const int64_t distinct = static_cast<int64_t>(found.first.size());
  for (const int64_t row : found.first) {
    int64_t words = 0;
    for (int64_t i = 0; i < length; ++i) words += ids[row * length + i] != pad_id;
    found.lengths.push_back(words);
  }
  found.order.resize(distinct);
  for (int64_t d = 0; d < distinct; ++d) found.order[d] = d;
  std::stable_sort(found.order.begin(), found.order.end(),
                   [&](int64_t a, int64_t b) { return found.lengths[a] > found.lengths[b]; });
  return found;
}

// The Python's encode on CPU in one call: each distinct sentence of `tokens` read once by every member's GRU,
// the summaries given back per row [members, rows, size]. Then, if `keep` and a sentence has words, what
// read_backward needs.
std::vector<at::Tensor> read_batch(const at::Tensor& tables, const at::Tensor& weight_hh, const at::Tensor& bias_hh,
                                   const at::Tensor& tokens_any, int64_t pad_id, int64_t trained, bool keep) {
  TORCH_CHECK(tables.is_cpu() && tokens_any.is_cpu(), "lanro_gru.read runs on CPU tensors");
  const at::Tensor tokens = tokens_any.contiguous();
  const Sentences found = find_sentences(tokens, pad_id, tables.size(1));
  const int64_t members = tables.size(0), size = weight_hh.size(2), rows = tokens.size(0), length = tokens.size(1);
  const int64_t distinct = static_cast<int64_t>(found.first.size());
  const int64_t* words = tokens.data_ptr<int64_t>();
  std::vector<int64_t> active, packed_ids;  // who reads a word at each step; the words, step after step
  for (int64_t t = 0; t < length; ++t) {
    int64_t k = 0;
    for (const int64_t d : found.order) {
      if (found.lengths[d] <= t) break;
      packed_ids.push_back(words[found.first[d] * length + t]);
      ++k;
    }
    if (k == 0) break;
    active.push_back(k);
  }
  if (active.empty()) return {at::zeros({members, rows, size}, tables.options())};  // no words: nothing to learn
  const auto index_options = tokens.options();
  const at::Tensor ids = at::tensor(packed_ids, index_options);
  std::vector<at::Tensor> out;
  AT_DISPATCH_FLOATING_TYPES(tables.scalar_type(), "lanro_gru.read", [&] {
    out = forward_typed<scalar_t>(tables.index_select(1, ids), weight_hh, bias_hh, active, trained, keep);
  });
  std::vector<int64_t> sorted_at(distinct);  // where each distinct sentence is among those read
  for (int64_t j = 0; j < distinct; ++j) sorted_at[found.order[j]] = j;
  at::Tensor summaries = at::zeros({members, rows, size}, tables.options());  // an empty sentence reads as zeros
  AT_DISPATCH_FLOATING_TYPES(tables.scalar_type(), "lanro_gru.read", [&] {
    const scalar_t* last = out[0].data_ptr<scalar_t>();  // [members, active[0], size], longest first
    scalar_t* target = summaries.data_ptr<scalar_t>();
    for (int64_t m = 0; m < members; ++m) {
      for (int64_t r = 0; r < rows; ++r) {
        const int64_t j = sorted_at[found.inverse[r]];
        if (j >= active[0]) continue;
        std::copy_n(last + (m * active[0] + j) * size, size, target + (m * rows + r) * size);
      }
    }
  });
  out[0] = summaries;
  if (keep) {
    for (const auto& values : {packed_ids, active, sorted_at, found.inverse}) out.push_back(at::tensor(values, index_options));
  }
  return out;
}

// The gradients of read's tables, recurrent weights and biases (zero for the members past `trained`), as
// autograd takes them through the Python's encode: the same ATen calls for what is not element-wise.
std::vector<at::Tensor> read_batch_backward(const at::Tensor& grad, const at::Tensor& weight_hh,
                                            const at::Tensor& before, const at::Tensor& rz, const at::Tensor& n,
                                            const at::Tensor& hidden_n, const at::Tensor& ids, const at::Tensor& active_t,
                                            const at::Tensor& sorted_at, const at::Tensor& inverse, int64_t members,
                                            int64_t vocab_size) {
  const int64_t size = grad.size(2), distinct = sorted_at.size(0), trained = weight_hh.size(0);
  const std::vector<int64_t> active(active_t.data_ptr<int64_t>(), active_t.data_ptr<int64_t>() + active_t.numel());
  // The members past `trained` learn nothing: their gradients stay zero, and nothing is computed for them.
  const auto options = grad.options();
  const at::Tensor learning = grad.slice(0, 0, trained);
  const at::Tensor by_sentence = at::zeros({trained, distinct, size}, options).index_add_(1, inverse, learning);
  const at::Tensor by_reading = at::zeros({trained, distinct, size}, options).index_add_(1, sorted_at, by_sentence);
  at::Tensor grad_tables = at::zeros({members, vocab_size, 3 * size}, options);
  at::Tensor grad_weight = at::zeros({members, 3 * size, size}, options);
  at::Tensor grad_bias = at::zeros({members, 3 * size}, options);
  AT_DISPATCH_FLOATING_TYPES(grad.scalar_type(), "lanro_gru.read_backward", [&] {
    const at::Tensor grad_inputs = backward_typed<scalar_t>(by_reading.slice(1, 0, active[0]), weight_hh, before, rz, n,
                                                            hidden_n, active, grad_weight.narrow(0, 0, trained),
                                                            grad_bias.narrow(0, 0, trained));
    grad_tables.narrow(0, 0, trained).index_add_(1, ids, grad_inputs);
  });
  return {grad_tables, grad_weight, grad_bias};
}

}  // namespace

// The namespace is native.py's READING.name. The kernels are CPU's, not catch-all ones, so that the operators
// stay whole where they are recorded (lanrocli/agent/replay.py): a catch-all kernel would be recorded as the
// calls it makes, with this batch's sentences among their constants.
TORCH_LIBRARY(lanro_gru, m) {
  m.def("read(Tensor tables, Tensor weight_hh, Tensor bias_hh, Tensor tokens, int pad_id, int trained, bool keep) "
        "-> Tensor[]");
  m.def(
      "read_backward(Tensor grad, Tensor weight_hh, Tensor before, Tensor rz, Tensor n, Tensor hidden_n, Tensor ids, "
      "Tensor active, Tensor sorted_at, Tensor inverse, int members, int vocab_size) -> Tensor[]");
}

TORCH_LIBRARY_IMPL(lanro_gru, CPU, m) {
  m.impl("read", &read_batch);
  m.impl("read_backward", &read_batch_backward);
}
