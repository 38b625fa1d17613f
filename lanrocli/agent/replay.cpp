// A recorded sequence of ATen operations, replayed from C++ (lanrocli/agent/replay.py records it).
//
// An update at batch 64 is a few hundred small operations, and on CPU each costs more to reach from Python,
// through autograd, than to compute. Replaying the operations that one update ran, forward and backward,
// as a list of dispatcher calls runs the same kernels on the same arguments, so it gives the same numbers bit
// for bit, without the interpreter or autograd between them. Calls that do not depend on each other can be
// made by two threads at once: each still computes what it computed alone.

#include <ATen/Parallel.h>
#include <ATen/core/dispatch/Dispatcher.h>
#include <torch/csrc/jit/python/pybind_utils.h>
#include <torch/extension.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <exception>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <unistd.h>

namespace py = pybind11;

namespace {

// One argument of a call: a value an earlier call made (or an input), a list of such values, or a constant.
struct Argument {
  enum class Kind { Value, Values, Constant } kind;
  int64_t slot = -1;
  std::vector<int64_t> slots;  // -1 for an optional tensor left out
  bool optional = false;       // the list is of optional tensors (Tensor?[])
  c10::IValue constant;
};

struct Call {
  c10::OperatorHandle op;
  std::vector<Argument> arguments;
  std::vector<int64_t> results;  // where each value the operator returns is kept
  bool unpack = false;           // the operator returns one list of tensors, whose elements go to `results`
  std::vector<int64_t> freed;  // values no later call reads, dropped after this one (calls made in order)
};

// The calls, and how threads take them (Program::schedule): in which order, per call how many calls it
// follows and which follow it and the values it reads, per value how many calls read it (-1: never dropped).
struct Plan {
  std::vector<Call> calls;
  int64_t threads = 1;
  pid_t process = 0;  // that scheduled it
  std::vector<int64_t> order;
  std::vector<int32_t> followed;
  std::vector<std::vector<int64_t>> next, reads;
  std::vector<int32_t> readers;
};

// The recorded operations are those autograd ran: replayed below it, they record no graph of their own. Each
// thread that makes calls holds this while it does.
using BelowAutograd = at::AutoDispatchBelowADInplaceOrView;

// One call on the values: its arguments pushed, the operator called, its results kept.
void make(const Call& call, std::vector<c10::IValue>& values, torch::jit::Stack& stack) {
  stack.clear();
  for (const Argument& argument : call.arguments) {
    switch (argument.kind) {
      case Argument::Kind::Value:
        stack.push_back(values[argument.slot]);
        break;
      case Argument::Kind::Values:
        if (argument.optional) {
          c10::List<std::optional<at::Tensor>> list;
          for (const int64_t slot : argument.slots)
            list.push_back(slot < 0 ? std::nullopt : std::optional<at::Tensor>(values[slot].toTensor()));
          stack.emplace_back(std::move(list));
        } else {
          c10::List<at::Tensor> list;
          list.reserve(argument.slots.size());
          for (const int64_t slot : argument.slots) list.push_back(values[slot].toTensor());
          stack.emplace_back(std::move(list));
        }
        break;
      case Argument::Kind::Constant:
        stack.push_back(argument.constant);
        break;
    }
  }
  call.op.callBoxed(stack);
  TORCH_CHECK(call.unpack || stack.size() >= call.results.size(), call.op.schema().name(), " returned ", stack.size(),
              " values, not ", call.results.size());
  if (call.unpack) {
    const c10::List<at::Tensor> list = stack[0].toTensorList();
    for (size_t k = 0; k < call.results.size(); ++k)
      if (call.results[k] >= 0) values[call.results[k]] = list.get(k);
  } else {
    for (size_t k = 0; k < call.results.size(); ++k)
      if (call.results[k] >= 0) values[call.results[k]] = std::move(stack[k]);
  }
}

// One replay made by several threads: the plan, the values, what each call still waits for, how many calls
// still read each value, which calls are taken. Every thread holds it through a shared pointer, so a helper
// that starts after the replay ended finds it whole, and finished.
class Together {
 public:
  Together(std::shared_ptr<const Plan> plan, std::vector<c10::IValue> values)
      : plan_(std::move(plan)),
        values_(std::move(values)),
        pending_(new std::atomic<int32_t>[plan_->calls.size()]),
        readers_(new std::atomic<int32_t>[values_.size()]),
        taken_(new std::atomic<bool>[plan_->calls.size()]) {
    for (size_t i = 0; i < plan_->calls.size(); ++i) {
      pending_[i].store(plan_->followed[i], std::memory_order_relaxed);
      taken_[i].store(false, std::memory_order_relaxed);
    }
    for (size_t slot = 0; slot < values_.size(); ++slot) readers_[slot].store(plan_->readers[slot], std::memory_order_relaxed);
  }

  // Takes the first call in the plan's order whose calls to follow are made, makes it, and again, until all
  // are made. A value is read only after the call that makes it counted itself made (release, acquire), and
  // dropped by the last call that reads it; an error stops every thread, and the replay's thread raises it.
  void take_calls() {
    const BelowAutograd below_autograd;
    const auto calls = static_cast<int64_t>(plan_->calls.size());
    torch::jit::Stack stack;
    try {
      // `seen` is read once a round: a call made after it ends the wait below, one made before it is seen.
      for (int64_t seen = made_.load(std::memory_order_acquire); seen < calls && !failed_.load(std::memory_order_relaxed);
           seen = made_.load(std::memory_order_acquire)) {
        int64_t first = first_.load(std::memory_order_relaxed);
        while (first < calls && taken_[first].load(std::memory_order_relaxed)) ++first;
        if (first > first_.load(std::memory_order_relaxed)) first_.store(first, std::memory_order_relaxed);
        int64_t call = -1;
        for (int64_t k = first; k < std::min(calls, first + kLookAhead) && call < 0; ++k) {
          if (taken_[k].load(std::memory_order_relaxed) || pending_[plan_->order[k]].load(std::memory_order_acquire) > 0) continue;
          if (!taken_[k].exchange(true, std::memory_order_acq_rel)) call = plan_->order[k];
        }
        if (call < 0) {
          wait_after(seen);
          continue;
        }
        make(plan_->calls[call], values_, stack);
        for (const int64_t slot : plan_->reads[call])
          if (readers_[slot].fetch_sub(1, std::memory_order_acq_rel) == 1) values_[slot] = c10::IValue();
        for (const int64_t next : plan_->next[call]) pending_[next].fetch_sub(1, std::memory_order_release);
        count_made();
      }
    } catch (...) {
      const std::lock_guard<std::mutex> lock(error_mutex_);
      if (!failed_.exchange(true)) error_ = std::current_exception();
    }
  }

  // The values once every call is made (the replay's thread, after its take_calls), or the error.
  const std::vector<c10::IValue>& values() {
    while (made_.load() < static_cast<int64_t>(plan_->calls.size()) && !failed_.load()) wait_after(made_.load());
    const std::lock_guard<std::mutex> lock(error_mutex_);
    if (error_) std::rethrow_exception(error_);
    return values_;
  }

 private:
  // How far past the first call not taken a thread looks for one it can make.
  static constexpr int64_t kLookAhead = 64;

  void count_made() { made_.fetch_add(1, std::memory_order_release); }

  // Until a call is made after `seen` calls were, or a call failed. Helpers run only where the machine has a
  // core to spare for them (replay.py), so a spin that yields takes nothing from other work.
  void wait_after(int64_t seen) {
    for (int spins = 0; made_.load(std::memory_order_acquire) == seen && !failed_.load(std::memory_order_relaxed); ++spins)
      if (spins > 64) std::this_thread::yield();
  }

  const std::shared_ptr<const Plan> plan_;
  std::vector<c10::IValue> values_;
  std::unique_ptr<std::atomic<int32_t>[]> pending_, readers_;
  std::unique_ptr<std::atomic<bool>[]> taken_;  // per place in the order
  std::atomic<int64_t> first_{0};  // every place before it is taken
  std::atomic<int64_t> made_{0};
  std::atomic<bool> failed_{false};
  std::mutex error_mutex_;
  std::exception_ptr error_;
};

// A constant as the dispatcher takes it. A Python number where the schema asks for a tensor becomes what
// torch's argument parser makes of it: a wrapped number, which type promotion treats as a scalar.
c10::IValue constant(const py::handle& value, const c10::TypePtr& type) {
  if (type->kind() == c10::TypeKind::TensorType && !THPVariable_Check(value.ptr())) {
    at::Tensor tensor = c10::scalar_to_tensor(torch::jit::toIValue(value, c10::NumberType::get()).toScalar());
    tensor.unsafeGetTensorImpl()->set_wrapped_number(true);
    return tensor;
  }
  return torch::jit::toIValue(value, type);
}

class Program {
 public:
  Program(int64_t slots, std::vector<int64_t> inputs, std::vector<int64_t> outputs)
      : slots_(slots), inputs_(std::move(inputs)), outputs_(std::move(outputs)), plan_(std::make_shared<Plan>()) {
    for (const auto* slots_of : {&inputs_, &outputs_})
      for (const int64_t slot : *slots_of) TORCH_CHECK(slot >= 0 && slot < slots_, "slot ", slot, " out of range");
  }

  // `arguments`: per argument of the operator's schema, in order, a pair (kind, payload): ("value", slot),
  // ("values", [slots]) or ("constant", a Python value, converted by the argument's type in the schema).
  void add(const std::string& name, const std::string& overload, const py::list& arguments,
           std::vector<int64_t> results, bool unpack, std::vector<int64_t> freed) {
    TORCH_CHECK(plan_->order.empty(), "a call added after the schedule: add every call first");
    const c10::OperatorHandle op = c10::Dispatcher::singleton().findSchemaOrThrow(name.c_str(), overload.c_str());
    const auto& schema = op.schema().arguments();
    TORCH_CHECK(arguments.size() == schema.size(), name, ".", overload, " takes ", schema.size(), " arguments, not ",
                arguments.size());
    Call call{op, {}, std::move(results), unpack, std::move(freed)};
    for (size_t i = 0; i < schema.size(); ++i) {
      const auto pair = arguments[i].cast<py::tuple>();
      const auto kind = pair[0].cast<std::string>();
      Argument argument;
      if (kind == "value") {
        argument.kind = Argument::Kind::Value;
        argument.slot = pair[1].cast<int64_t>();
      } else if (kind == "values") {
        argument.kind = Argument::Kind::Values;
        argument.slots = pair[1].cast<std::vector<int64_t>>();
        const auto list = schema[i].type()->cast<c10::ListType>();
        argument.optional = list && list->getElementType()->kind() == c10::TypeKind::OptionalType;
      } else {
        TORCH_CHECK(kind == "constant", "unknown argument kind ", kind);
        argument.kind = Argument::Kind::Constant;
        argument.constant = constant(pair[1], schema[i].type());
      }
      call.arguments.push_back(std::move(argument));
    }
    // A slot out of range would read or write past the values: checked once here, not at every replay.
    const auto check = [&](int64_t slot, bool may_be_absent) {
      TORCH_CHECK(slot < slots_ && (slot >= 0 || (may_be_absent && slot == -1)), name, ": slot ", slot, " out of range");
    };
    for (const Argument& argument : call.arguments) {
      if (argument.kind == Argument::Kind::Value) check(argument.slot, false);
      for (const int64_t slot : argument.slots) check(slot, argument.optional);
    }
    for (const int64_t slot : call.results) check(slot, true);
    for (const int64_t slot : call.freed) check(slot, false);
    plan_->calls.push_back(std::move(call));
  }

  // From now on `threads` threads make the calls together, each taking the first call in `order` whose
  // calls in `after` are made, and the replay's own thread whatever the others leave (a helper that starts
  // late, on a busy machine, costs nothing). `order` must follow `after`, and `after` every value a call
  // reads (both checked) and every change in place. Every call computes what it did alone.
  void schedule(int64_t threads, std::vector<int64_t> order, const std::vector<std::vector<int64_t>>& after) {
    Plan& plan = *plan_;
    const auto calls = static_cast<int64_t>(plan.calls.size());
    TORCH_CHECK(plan.order.empty(), "the program is scheduled already");  // a replay in flight may be reading it
    TORCH_CHECK(threads >= 1 && order.size() == plan.calls.size() && after.size() == plan.calls.size(),
                "a schedule takes a thread count, and an order and the calls to follow for each call");
    std::vector<int64_t> place(calls, -1);
    for (int64_t k = 0; k < calls; ++k) {
      TORCH_CHECK(order[k] >= 0 && order[k] < calls && place[order[k]] < 0, "the order is not of the program's calls");
      place[order[k]] = k;
    }
    std::vector<int64_t> made_by(slots_, -1);
    for (int64_t i = 0; i < calls; ++i)
      for (const int64_t slot : plan.calls[i].results)
        if (slot >= 0) made_by[slot] = i;
    plan.followed.assign(calls, 0);
    plan.next.assign(calls, {});
    plan.reads.assign(calls, {});
    plan.readers.assign(slots_, 0);
    for (int64_t i = 0; i < calls; ++i) {
      std::vector<int64_t> before(after[i]);
      std::sort(before.begin(), before.end());
      before.erase(std::unique(before.begin(), before.end()), before.end());
      for (const int64_t d : before) {
        TORCH_CHECK(d >= 0 && d < calls && place[d] < place[i], "call ", i, " follows call ", d, ", which the order puts after it");
        plan.next[d].push_back(i);
      }
      plan.followed[i] = static_cast<int32_t>(before.size());
      std::vector<int64_t>& reads = plan.reads[i];
      for (const Argument& argument : plan.calls[i].arguments) {
        if (argument.kind == Argument::Kind::Value) reads.push_back(argument.slot);
        for (const int64_t slot : argument.slots)
          if (slot >= 0) reads.push_back(slot);
      }
      std::sort(reads.begin(), reads.end());
      reads.erase(std::unique(reads.begin(), reads.end()), reads.end());
      for (const int64_t slot : reads) {
        TORCH_CHECK(made_by[slot] < 0 || std::binary_search(before.begin(), before.end(), made_by[slot]), "call ", i,
                    " reads what call ", made_by[slot], " makes without following it");
        ++plan.readers[slot];
      }
    }
    for (const auto* kept : {&inputs_, &outputs_})
      for (const int64_t slot : *kept) plan.readers[slot] = -1;
    plan.order = std::move(order);
    plan.threads = threads;
    plan.process = getpid();
  }

  std::vector<at::Tensor> run(const std::vector<at::Tensor>& inputs) const {
    const BelowAutograd below_autograd;
    // In a process forked from the one that scheduled it, torch's inter-op pool has no threads: one after another.
    if (plan_->threads > 1 && getpid() == plan_->process) {
      const auto together = std::make_shared<Together>(plan_, start(inputs));
      // A helper whose calls would split their work over another number of threads than this thread's could
      // round differently: it leaves them all to this one.
      const int within = at::get_num_threads();
      for (int64_t k = 1; k < plan_->threads; ++k)
        at::launch([together, within] {
          if (at::get_num_threads() == within) together->take_calls();
        });
      together->take_calls();
      return finish(together->values());
    }
    std::vector<c10::IValue> values = start(inputs);
    torch::jit::Stack stack;
    for (const Call& call : plan_->calls) {
      make(call, values, stack);
      for (const int64_t slot : call.freed) values[slot] = c10::IValue();
    }
    return finish(values);
  }

  // The calls one after another, and the nanoseconds each took: what an order is planned on.
  std::pair<std::vector<at::Tensor>, std::vector<int64_t>> timed(const std::vector<at::Tensor>& inputs) const {
    const BelowAutograd below_autograd;
    std::vector<c10::IValue> values = start(inputs);
    std::vector<int64_t> times;
    times.reserve(plan_->calls.size());
    torch::jit::Stack stack;
    for (const Call& call : plan_->calls) {
      const auto begin = std::chrono::steady_clock::now();
      make(call, values, stack);
      times.push_back(std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - begin).count());
    }
    return {finish(values), times};
  }

 private:
  std::vector<c10::IValue> start(const std::vector<at::Tensor>& inputs) const {
    TORCH_CHECK(inputs.size() == inputs_.size(), "the program takes ", inputs_.size(), " inputs, not ", inputs.size());
    std::vector<c10::IValue> values(slots_);
    for (size_t i = 0; i < inputs.size(); ++i) values[inputs_[i]] = inputs[i];
    return values;
  }

  std::vector<at::Tensor> finish(const std::vector<c10::IValue>& values) const {
    std::vector<at::Tensor> outputs;
    outputs.reserve(outputs_.size());
    for (const int64_t slot : outputs_) outputs.push_back(values[slot].toTensor());
    return outputs;
  }

  int64_t slots_;
  std::vector<int64_t> inputs_, outputs_;
  std::shared_ptr<Plan> plan_;  // shared with the replays in flight, which may outlive a call to run
};

}  // namespace

PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
  py::class_<Program>(m, "Program")
      .def(py::init<int64_t, std::vector<int64_t>, std::vector<int64_t>>())
      .def("add", &Program::add)
      .def("schedule", &Program::schedule)
      .def("run", &Program::run, py::call_guard<py::gil_scoped_release>())
      .def("timed", &Program::timed, py::call_guard<py::gil_scoped_release>());
}
